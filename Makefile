# The README's two commands: `make plan` and `make test`. Each sets up .venv itself.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: plan test bench bench-quick bench-croco clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

plan: $(STAMP)
	$(VENV)/bin/thermo-ddp compare --payload-kg 40 --hold-s 60

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

bench-quick: $(STAMP)
	$(PY) benchmarks/run_all.py --quick

bench-croco: $(STAMP)
	$(PY) benchmarks/bench_arm_crocoddyl.py

clean:
	rm -rf $(VENV) .venv-croco build src/*.egg-info .pytest_cache
