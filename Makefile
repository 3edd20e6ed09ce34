# The README's two commands: `make plan` and `make test`. Each sets up .venv itself.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: plan test wheel-smoke bench bench-quick bench-croco clean

$(STAMP): pyproject.toml
	@echo "== creating $(VENV) with $(PYTHON)"
	$(PYTHON) -m venv $(VENV)
	@echo "== installing thermo-ddp and its dependencies into $(VENV) (first run: a few minutes)"
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install -e ".[dev]"
	touch $(STAMP)
	@echo "== installed: run $(VENV)/bin/thermo-ddp, or 'source $(VENV)/bin/activate' and then thermo-ddp"

plan: $(STAMP)
	$(VENV)/bin/thermo-ddp compare --payload-kg 40 --hold-s 60

test: $(STAMP)
	$(PY) -m pytest -q

# The wheel, installed into a fresh venv, plans from a temporary folder (CI runs it after `make test`).
wheel-smoke:
	PYTHON=$(PYTHON) .ci/wheel-smoke

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

bench-quick: $(STAMP)
	$(PY) benchmarks/run_all.py --quick

bench-croco: $(STAMP)
	$(PY) benchmarks/bench_arm_crocoddyl.py

clean:
	rm -rf $(VENV) .venv-croco build dist src/*.egg-info .pytest_cache
