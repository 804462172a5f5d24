# Two entry points for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
OUT ?= demo_out

.PHONY: demo test venv bench clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	touch $@

venv: $(VENV)/.installed

## demo: analyse every scan in sample_images/ and write tables, figures and ensemble statistics into $(OUT)/
demo: venv
	$(PY) -m crosssection batch sample_images --out $(OUT)/batch --workers 2
	$(PY) -m crosssection stats $(OUT)/batch --out $(OUT)/report
	@echo "demo written to $(OUT)/ (open $(OUT)/report/report.html)"

## test: the whole test suite on 2 cores
test: venv
	$(PY) -m pytest -n 2 -q

bench: venv
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) $(OUT)
