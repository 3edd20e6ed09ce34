# The README's two commands: `make plan` and `make test`. Each sets up .venv itself.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: plan test docs notebooks wheel-smoke bench bench-quick bench-croco bench-drake clean

DOCS_STAMP := $(VENV)/.docs-installed

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

# Two workers (the 2-core machine the suite is sized for), a test file per worker at a time (its fixtures shared).
test: $(STAMP) $(DOCS_STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile

# The documentation site: the docs extra (Sphinx, MyST, furo) into .venv, then the HTML into docs/_build/html,
# every warning an error (a docstring autodoc cannot read, a broken link, a public name with no API entry);
# -E: read every page again, since autodoc does not notice a changed docstring.
$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(VENV)/bin/sphinx-build -E -W --keep-going -q -b html docs docs/_build/html
	@echo "== the site is in docs/_build/html (open docs/_build/html/index.html)"

# Re-execute the notebooks in place (full configuration, quiet) and check them for leftovers.
notebooks: $(STAMP)
	$(PY) notebooks/execute.py

# The wheel, installed into a fresh venv, plans from a temporary folder (CI runs it after `make test`).
wheel-smoke:
	PYTHON=$(PYTHON) .ci/wheel-smoke

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

bench-quick: $(STAMP)
	$(PY) benchmarks/run_all.py --quick

bench-croco: $(STAMP)
	$(PY) benchmarks/bench_arm_crocoddyl.py

# The optional Drake peer (SNOPT on the lift's transcription): its own venv, never needed by the tests.
DRAKE_VENV  := .venv-drake
DRAKE_STAMP := $(DRAKE_VENV)/.installed

$(DRAKE_STAMP): pyproject.toml benchmarks/requirements-drake.txt
	@echo "== creating $(DRAKE_VENV) with $(PYTHON): thermo-ddp + benchmarks/requirements-drake.txt (pydrake)"
	$(PYTHON) -m venv $(DRAKE_VENV)
	$(DRAKE_VENV)/bin/python -m pip install --upgrade pip
	$(DRAKE_VENV)/bin/python -m pip install -e . -r benchmarks/requirements-drake.txt
	touch $(DRAKE_STAMP)

bench-drake: $(DRAKE_STAMP)
	$(DRAKE_VENV)/bin/python benchmarks/bench_lift_drake.py

clean:
	rm -rf $(VENV) .venv-croco $(DRAKE_VENV) build dist src/*.egg-info .pytest_cache docs/_build
