"""Mutation fuzzer of the SPX host side: SelspotDecoder and the MCS-1 reply parser.

TARGETS.md: every decoder is fuzzed with >= 1 000 000 mutated inputs and only
the documented protocol errors may be raised. This is a seeded, bounded,
self-contained fuzzer (no atheris, no network), too long for ``make test``;
``benchmarks/fuzz_selspot.py`` runs it.

Modules, by job:

* :mod:`fuzzing.streams` builds valid SPX streams from the spec;
* :mod:`fuzzing.mutations` damages them (frame-aware and blind) and cuts them
  into reads;
* :mod:`fuzzing.invariants` feeds each input to three decoders and checks
  what must hold after every call;
* :mod:`fuzzing.replies` mutates reply lines and checks the reply parser;
* :mod:`fuzzing.runner` runs the workers, reports progress, prints the JSON
  summary, saves and replays the first failure.
"""
