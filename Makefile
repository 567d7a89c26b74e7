# Two commands on a fresh machine: `make demo` and `make test`. Both bootstrap .venv themselves.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench package clean venv

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

bench: $(STAMP)
	$(PY) bench/flatten_table.py

package: $(STAMP)
	$(PY) tools/package.py --out dist

clean:
	rm -rf $(VENV) out dist wheels
