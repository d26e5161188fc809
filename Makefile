# raplas-hdl: set-up and run targets. `make demo` and `make test` install what is missing.
PYTHON  ?= python3
VENV    ?= .venv
VPY     := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
JOBS    ?= 2
PYTEST  := $(VPY) -m pytest -n $(JOBS) --durations=25

.PHONY: all setup sysdeps demo verilog test test-full bench campaign synth constraints wheel lint clean distclean

all: demo

sysdeps:
	@$(PYTHON) tools/bootstrap.py

$(STAMP): pyproject.toml requirements.lock
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python 3.11+ needed"'
	$(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install -q --upgrade pip
	$(VPY) -m pip install -q -r requirements.lock
	$(VPY) -m pip install -q --no-deps -e .
	@touch $@

setup: sysdeps $(STAMP)

## The main job: emit the Verilog of every unit and render the default scene.
demo: setup
	$(VENV)/bin/raplas-hdl demo

verilog: setup
	$(VPY) -c 'from raplas_hdl.rtl.units import emit_all; [print(p) for p in emit_all("build/verilog")]'

## The tests (about 20 minutes on 2 quiet cores from a fresh clone; both simulators, place and route, proofs).
test: setup
	$(VENV)/bin/lint-imports
	$(PYTEST) -m "not full" tests

## Long campaigns on top of the tests.
test-full: setup
	$(VENV)/bin/lint-imports
	$(PYTEST) tests

bench: setup
	$(VENV)/bin/raplas-hdl bench

## The stress campaign (resumable: run it again after an interruption).
campaign: setup
	$(VENV)/bin/raplas-hdl stress campaign

constraints: setup
	$(VENV)/bin/raplas-hdl constraints --check

synth: setup
	$(VENV)/bin/raplas-hdl synth all

## The sdist and the wheel, into build/dist (docs/integration.md).
wheel: setup
	$(VPY) -m build --no-isolation --outdir build/dist .

clean:
	rm -rf build .pytest_cache

distclean: clean
	rm -rf $(VENV)
