#!/usr/bin/env bash
# import-linter walks a package's folder, but spotlab maps spotlab.drivers and
# spotlab.simulators from other folders (package-dir). Mirror the installed
# layout in a scratch folder and check the contracts of pyproject.toml there.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
cp -r "$root/src/spotlab" "$scratch/spotlab"
cp -r "$root/drivers" "$scratch/spotlab/drivers"
cp -r "$root/simulators" "$scratch/spotlab/simulators"
find "$scratch" -name __pycache__ -prune -exec rm -rf {} +
cd "$scratch"
PYTHONPATH="$scratch" "${LINT_IMPORTS:-lint-imports}" --config "$root/pyproject.toml" --no-cache
