"""Mutation fuzzing of every other decoder and reader (TMR, CEN, CSX, WSX frames and control
replies, journal, C3D, TRC, rig TOML, marker-model JSON): only spotlab's documented errors
may come out.

Prints one JSON object per target: inputs, inputs that ended in a documented spotlab
error, unexpected exceptions by type and place. Inputs that raised something else are
written to ``--failure-dir`` for replay. The harness is
:mod:`spotlab.testing.fuzz`; the SPX decoder has its own (``fuzz_selspot.py``).

Usage: ``python benchmarks/fuzz_all.py [--inputs 1000000] [--targets tmr cen ...]
[--workers 2] [--seed 0] [--failure-dir DIR]``
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from spotlab.testing.fuzz import TARGETS, FuzzResult, fuzz

CHUNK = 5000


def _run(job: tuple[str, int, int]) -> FuzzResult:
    target, n, seed = job
    return fuzz(target, n, seed=seed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--inputs", type=int, default=1_000_000, help="inputs per target")
    ap.add_argument("--targets", nargs="+", default=list(TARGETS), choices=list(TARGETS))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--failure-dir", type=Path, default=None)
    args = ap.parse_args()
    for target in args.targets:
        jobs = [
            (target, min(CHUNK, args.inputs - k), args.seed * 1_000_003 + k // CHUNK)
            for k in range(0, args.inputs, CHUNK)
        ]
        total = FuzzResult(target)
        with ProcessPoolExecutor(args.workers) as pool:
            for part in pool.map(_run, jobs):
                total.inputs += part.inputs
                total.documented += part.documented
                total.seconds += part.seconds
                for key, (n, data) in part.findings.items():
                    old = total.findings.get(key, (0, data))
                    total.findings[key] = (old[0] + n, old[1])
        if args.failure_dir is not None:
            args.failure_dir.mkdir(parents=True, exist_ok=True)
            for i, (_, data) in enumerate(total.findings.values()):
                (args.failure_dir / f"{target}-{i}.bin").write_bytes(data)
        print(json.dumps({"bench": "fuzz", **total.to_dict()}), flush=True)


if __name__ == "__main__":
    main()
