# The two commands of the README quick start. Each creates .venv and installs
# what it needs on a fresh machine with Python 3.11+ and make.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp

.PHONY: demo test lint typecheck layers unit long hil bench bench-gcvspline fuzz clean

# setup.py and the kernels' C sources too: an editable install compiles them once.
$(STAMP): pyproject.toml setup.py $(shell find src -name '_c_*.c' -o -name '_*.h')
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "spotlab needs Python 3.11 or newer"'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	@# PYTHONWARNINGS: setuptools' build backend warns about every editable install
	PYTHONWARNINGS=ignore $(BIN)/python -m pip install --quiet -e '.[dev,lsl,oak,console,usb]'
	@# The browser tests of the console (tests/browser) drive Debian's chromium.
	@if [ ! -x /usr/bin/chromium ]; then \
		if [ "$$(id -u)" = 0 ]; then apt-get install -y chromium || \
			(apt-get update && apt-get install -y chromium); \
		else echo "note: the console's browser tests need chromium: sudo apt-get install chromium"; fi; \
	fi
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/spotlab demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy src/spotlab drivers simulators

layers: $(STAMP)
	LINT_IMPORTS=$(CURDIR)/$(BIN)/lint-imports tools/lint_layers.sh

# Two workers (pytest-xdist), the tests spread over both; a module marked with an
# xdist_group runs on one worker, so its session-scoped recordings are made once.
unit: $(STAMP)
	$(BIN)/python -m pytest -m "not long" -n 2 --dist loadgroup

# The 30-60 s versions of end-to-end runs (make test runs them at 8-10 s).
long: $(STAMP)
	$(BIN)/python -m pytest -m long

test: lint typecheck layers unit

# The shipped hardware-in-the-loop scenarios (docs/hil.md), each a pytest test through
# the --hil option; the 1 h soak is left out (spotlab hil run soak).
HIL_SCENARIOS := gait-lab fault-storm clock-torture scaled-lab labelled-hub
hil: $(STAMP)
	$(BIN)/python -m pytest $(addprefix --hil ,$(HIL_SCENARIOS))

bench: $(STAMP)
	PYTHONWARNINGS=ignore $(BIN)/python -m pip install --quiet -e '.[dev,bench]'
	$(BIN)/python benchmarks/run_all.py

# The gcvspline peer of benchmarks/spline_gcv.py: an sdist built with numpy.distutils,
# which needs gfortran and setuptools < 70 in its build environment.
bench-gcvspline: $(STAMP)
	command -v gfortran >/dev/null || apt-get install -y gfortran
	printf 'setuptools<70\n' > $(VENV)/gcvspline-build-constraint.txt
	$(BIN)/python -m pip install --quiet gcvspline==0.5 \
		--build-constraint $(VENV)/gcvspline-build-constraint.txt

# One million mutated inputs through every SPX decoder path (about 20 minutes on 2 cores),
# then one million through each other decoder and reader (TMR, CEN, journal, C3D, TRC,
# rig TOML, marker-model JSON: several hours on 2 cores).
fuzz: $(STAMP)
	$(BIN)/python benchmarks/fuzz_selspot.py --inputs 1000000 --workers 2
	$(BIN)/python benchmarks/fuzz_all.py --inputs 1000000 --workers 2 --failure-dir fuzz-failures

clean:
	rm -rf $(VENV) build *.egg-info .mypy_cache .ruff_cache
