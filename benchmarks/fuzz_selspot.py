"""Mutation fuzzer of the SPX host side: SelspotDecoder and the MCS-1 reply parser.

TARGETS.md: every decoder is fuzzed with >= 1 000 000 mutated inputs and only
the documented protocol errors may be raised. The fuzzer lives in the package
``fuzzing`` next to this script (streams, mutations, invariants, replies,
runner); docs/benchmarks.md describes what it checks and what it prints.

Usage: ``python benchmarks/fuzz_selspot.py [--inputs 1000000] [--seed 0] [--workers 2]
[--seconds S] [--failure-dir DIR] [--replay FILE]``
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not a package

from fuzzing.runner import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
