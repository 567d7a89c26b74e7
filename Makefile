# Two commands on a fresh machine: `make demo` and `make test`. Both bootstrap .venv themselves.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-numpy2 test-blender52 lint bench package clean venv

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-dev.txt
	touch $(STAMP)

demo: $(STAMP)
	$(PY) tools/demo.py --out out/demo

# CONFORMAL_NO_SKIP=1: a skipped test fails the run. Blender's user resources go to a temporary folder
# of the run's own (tests/conftest.py), removed at its end.
test: $(STAMP)
	CONFORMAL_NO_SKIP=1 $(PY) -m pytest -q tests

lint: $(STAMP)
	$(PY) -m ruff check .

# The core alone (no bpy) on numpy 2, with the scipy we ship: the core must run on both numpy lines.
NP2 := .venv-numpy2
$(NP2)/.installed: requirements.txt
	$(PYTHON) -m venv $(NP2)
	$(NP2)/bin/python -m pip install --quiet --upgrade pip
	$(NP2)/bin/python -m pip install --quiet numpy==2.4.6 scipy==1.15.3 scikit-fmm==2025.6.23 cvxopt==1.3.2 highspy==1.16.0 \
	    pytest==8.4.2 hypothesis==6.140.2
	touch $(NP2)/.installed

test-numpy2: $(NP2)/.installed
	$(NP2)/bin/python -m pytest -q tests --ignore-glob='tests/test_addon*'

# Blender 5.1 / 5.2 LTS (Python 3.13): the whole suite with bpy 5.2.3 (requirements-blender52.txt), in a
# Debian trixie root that tools/py313.sh builds once per requirements hash (needs root and Debian packages).
test-blender52:
	bash tools/py313.sh setup
	bash tools/py313.sh run sh -c 'CONFORMAL_NO_SKIP=1 python -m pytest -q tests'

bench: $(STAMP)
	$(PY) bench/flatten_table.py

# Zips for Python 3.11 (Blender 4.2-5.0) and 3.13 (5.1, 5.2 LTS); the cp313 Linux scikit-fmm wheel is
# built in the Python 3.13 root, set up here when this machine can (root, Debian packages).
package: $(STAMP)
	@if bash tools/py313.sh check; then bash tools/py313.sh setup; \
	else echo "package: no Python 3.13 root here, so no Linux scikit-fmm wheel for Blender 5.1/5.2 (see README)"; fi
	$(PY) tools/package.py --out dist

clean:
	rm -rf $(VENV) $(NP2) out dist wheels
