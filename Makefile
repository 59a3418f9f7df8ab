# Two commands on a fresh machine (Python 3.11, pip, make): `make run`, `make test`.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[test]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/tracker run

test: $(STAMP) lint
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check tracker plc tests bench

bench: $(STAMP)
	$(BIN)/python bench/bench.py
	$(BIN)/python bench/real_videos.py

clean:
	rm -rf $(VENV) .pytest_cache
