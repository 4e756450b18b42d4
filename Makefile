# pfjax: two commands do all the set-up on a fresh machine with Python >= 3.11 and make.
#   make study   creates .venv, installs pfjax, runs the paper reproduction and the default
#                Monte Carlo robustness study into results/
#   make test    creates .venv if needed, installs, runs the test suite
# Both install the exact versions in constraints.txt (the ones the tests and the README's numbers
# come from); make lock refreshes them to the newest that pyproject.toml's ranges allow.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=

.PHONY: study test install clean lock

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

study: $(STAMP)
	$(PY) studies/paper_reproduction.py
	$(VENV)/bin/pfjax study studies/robustness_default.toml

# pytest exits 5 when it collects no test: .ci/run fails on it too (a suite that ran nothing).
# --dist worksteal: an idle worker takes queued tests from the busy one (the slow tests come last).
test: $(STAMP)
	$(PY) -m pytest -n 2 --dist worksteal --durations=25 $(PYTEST_ARGS)

# The newest versions pip resolves for pyproject.toml's ranges, written to constraints.txt (its
# comment lines kept); then run make test and commit both.
LOCK_VENV := .venv-lock
lock:
	rm -rf $(LOCK_VENV)
	$(PYTHON) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(LOCK_VENV)/bin/python -m pip install --quiet ".[test]"
	{ grep '^#' constraints.txt; $(LOCK_VENV)/bin/python -m pip freeze --exclude-editable | grep -v -i '^pfjax[ =@]'; } > constraints.txt.new
	mv constraints.txt.new constraints.txt
	rm -rf $(LOCK_VENV) build

clean:
	rm -rf $(VENV) .pytest_cache results/paper_reproduction results/robustness_default
