# Two commands on a fresh machine: `make demo` and `make test`. Both bootstrap .venv themselves.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-numpy2 lint bench package clean venv

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-dev.txt
	touch $(STAMP)

demo: $(STAMP)
	$(PY) tools/demo.py --out out/demo

test: $(STAMP)
	BLENDER_USER_RESOURCES=$$(mktemp -d) $(PY) -m pytest -q tests

lint: $(STAMP)
	$(PY) -m ruff check .

# The core alone (no bpy) on numpy 2, with the scipy we ship: the core must run on both numpy lines.
NP2 := .venv-numpy2
$(NP2)/.installed: requirements.txt
	$(PYTHON) -m venv $(NP2)
	$(NP2)/bin/python -m pip install --quiet --upgrade pip
	$(NP2)/bin/python -m pip install --quiet numpy==2.4.6 scipy==1.15.3 scikit-fmm==2025.6.23 \
	    pytest==8.4.2 hypothesis==6.140.2
	touch $(NP2)/.installed

test-numpy2: $(NP2)/.installed
	$(NP2)/bin/python -m pytest -q tests --ignore-glob='tests/test_addon*'

bench: $(STAMP)
	$(PY) bench/flatten_table.py

package: $(STAMP)
	$(PY) tools/package.py --out dist

clean:
	rm -rf $(VENV) $(NP2) out dist wheels
