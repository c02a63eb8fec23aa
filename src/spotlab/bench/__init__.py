"""Device test benches: a family's conformance suite and its timing figures on one port.

``spotlab bench`` (``spotlab.console.commands.bench``) runs, for every device, the
conformance suite of its family (:mod:`spotlab.bench.conformance`), then streams and
measures frame-arrival jitter, host latency per frame, throughput against the line's
capacity and the device clock against the host (:mod:`spotlab.bench.measure`,
:mod:`spotlab.bench.timing`), optionally the recovery from a reset and a pulled cable
(:mod:`spotlab.bench.disruptive`), and writes ``report.json`` and ``report.html``
(:mod:`spotlab.bench.report`), compared with a baseline (:mod:`spotlab.bench.compare`).
"""
