# pfjax: two commands do all the set-up on a fresh machine with Python >= 3.11 and make.
#   make study   creates .venv, installs pfjax, runs the paper reproduction and the default
#                Monte Carlo robustness study into results/
#   make test    creates .venv if needed, installs, runs the test suite
#   make docs    builds the documentation site into site/ (executing the notebooks)
# Both install pfjax with its test, bench (Numba) and docs extras at the exact versions in
# constraints.txt (the ones the tests and the README's numbers come from); make lock refreshes them
# to the newest that pyproject.toml's ranges allow.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=

.PHONY: study test docs lint install clean lock

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e ".[test,bench,docs]"
	touch $(STAMP)

install: $(STAMP)

# The last lines run the README's first commands once, so that the persistent compilation cache
# (~/.cache/pfjax/xla) holds their programs and a user's first pfjax simulate or pfjax track starts warm.
study: $(STAMP)
	$(PY) studies/paper_reproduction.py
	$(VENV)/bin/pfjax study studies/robustness_default.toml
	$(VENV)/bin/pfjax simulate --path sine --controller mixed --beta-r-deg 5 --beta-f-deg 5 --horizon 20 --json > /dev/null
	$(VENV)/bin/pfjax simulate --path sine --controller pi --json > /dev/null
	$(VENV)/bin/pfjax track --json > /dev/null

# pytest exits 5 when it collects no test: .ci/run fails on it too (a suite that ran nothing).
# --dist worksteal: an idle worker takes queued tests from the busy one (the slow tests come last).
test: $(STAMP)
	$(PY) -m pytest -n 2 --dist worksteal --durations=25 $(PYTEST_ARGS)

# The documentation site: mkdocs-material, the API reference from the docstrings (mkdocstrings),
# the notebooks executed and rendered (mkdocs-jupyter). --strict: a broken link, a missing page or
# reference, or a docstring warning fails the build. The test suite builds it too (without
# executing the notebooks, which tests/test_notebooks.py runs).
# The notebooks' temporary outputs (notebook 02's study) go to a directory removed after the build.
docs: $(STAMP)
	tmp=$$(mktemp -d) && NO_MKDOCS_2_WARNING=1 TMPDIR=$$tmp $(VENV)/bin/mkdocs build --strict; \
		rc=$$?; rm -rf $$tmp; exit $$rc

# Lint and types (also run by the test suite, tests/test_lint.py); the rules are in pyproject.toml.
LINT_TARGETS := pfjax studies tests docs/hooks.py
lint: $(STAMP)
	$(VENV)/bin/ruff check $(LINT_TARGETS)
	$(VENV)/bin/ruff format --check $(LINT_TARGETS)
	$(VENV)/bin/mypy

# The newest versions pip resolves for pyproject.toml's ranges, written to constraints.txt (its
# comment lines kept; --all: setuptools is a test dependency, pip freeze leaves it out otherwise);
# then run make test and commit both.
LOCK_VENV := .venv-lock
lock:
	rm -rf $(LOCK_VENV)
	$(PYTHON) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(LOCK_VENV)/bin/python -m pip install --quiet ".[test,bench,docs]"
	{ grep '^#' constraints.txt; $(LOCK_VENV)/bin/python -m pip freeze --all --exclude-editable | grep -v -i -E '^(pfjax|pip)[ =@]'; } > constraints.txt.new
	mv constraints.txt.new constraints.txt
	rm -rf $(LOCK_VENV) build

clean:
	rm -rf $(VENV) .pytest_cache site .cache results/paper_reproduction results/robustness_default
