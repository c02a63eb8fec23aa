"""Run every benchmark script in this folder; each prints JSON lines on stdout.

Usage: ``python benchmarks/run_all.py [NAME ...]`` (names without ``.py``).
Figures are measurements on a shared, noisy machine: compare ratios within one run.
The fuzzers (``fuzz_*.py``, about 20 minutes each) run only when named, or by
``make fuzz``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    scripts = sorted(p for p in HERE.glob("*.py") if p.name != Path(__file__).name)
    if argv:
        wanted = set(argv)
        scripts = [p for p in scripts if p.stem in wanted]
    else:
        scripts = [p for p in scripts if not p.stem.startswith("fuzz_")]
    failed = 0
    for script in scripts:
        print(f"# {script.name}", file=sys.stderr, flush=True)
        result = subprocess.run([sys.executable, str(script)], check=False)
        failed += result.returncode != 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
