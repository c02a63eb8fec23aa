"""Hardware-in-the-loop scenario runs: simulators as processes, the lab's own code paths.

A scenario file (TOML, docs/hil.md) is a lab file with simulators behind its
devices, a motion, faults, processing steps and pass criteria
(:mod:`spotlab.hil.scenario`). :mod:`spotlab.hil.runner` starts every simulator as
its own process, records and processes with the code ``spotlab record`` and
:mod:`spotlab.processing` use, and scores against the simulators' truth at the end.
"""
