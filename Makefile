# pfjax: two commands do all the set-up on a fresh machine with Python >= 3.11 and make.
#   make study   creates .venv, installs pfjax, runs the paper reproduction and the default
#                Monte Carlo robustness study into results/
#   make test    creates .venv if needed, installs, runs the test suite
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PYTEST_ARGS ?=

.PHONY: study test install clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

study: $(STAMP)
	$(PY) studies/paper_reproduction.py
	$(VENV)/bin/pfjax study studies/robustness_default.toml

# pytest exits 5 when it collects no test: .ci/run fails on it too (a suite that ran nothing).
# --dist worksteal: an idle worker takes queued tests from the busy one (the slow tests come last).
test: $(STAMP)
	$(PY) -m pytest -n 2 --dist worksteal --durations=25 $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) .pytest_cache results/paper_reproduction results/robustness_default
