# Two commands on a fresh machine (Python 3.11, pip, make): `make run`, `make test`.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test lint bench demo clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[test]'
	touch $(STAMP)

run: $(STAMP)
	@echo "make run: to type 'tracker' yourself, run '. $(VENV)/bin/activate' first (or call $(BIN)/tracker)"
	@echo "make run: the live view is at http://127.0.0.1:8080/ while the demo plays"
	$(BIN)/tracker run --web 127.0.0.1:8080

# Two workers (this is a 2-core machine); --dist loadfile keeps each file's cached scenes in one worker.
test: $(STAMP) lint
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

lint: $(STAMP)
	$(BIN)/ruff check tracker plc tests bench

bench: $(STAMP)
	$(BIN)/python bench/bench.py
	$(BIN)/python bench/real_videos.py
	$(BIN)/python bench/belt_motion.py
	$(BIN)/python bench/faint_faces.py
	$(BIN)/python bench/faint_faces.py --parts 5
	$(BIN)/python bench/heights.py
	$(BIN)/python bench/heights_random.py
	$(BIN)/python bench/heights_random.py --any-height
	$(BIN)/python bench/heights_random.py --tilt 25 --scenes 15
	$(BIN)/python bench/heights_random.py --dark --scenes 60
	$(BIN)/python bench/heights_random.py --textured --scenes 30
	$(BIN)/python bench/heights_random.py --height 3 --scenes 24
	$(BIN)/python bench/heights_random.py --side-light --scenes 60
	$(BIN)/python bench/heights_random.py --shadow --scenes 60
	$(BIN)/python bench/heights_random.py --near --scenes 30
	$(BIN)/python bench/heights_random.py --two-parts --scenes 30
	$(BIN)/python bench/issue_scenes.py
	$(BIN)/python bench/view_heights.py

# Remakes the bundled demo recording (the same bytes for the same software: no wall-clock time in it).
demo: $(STAMP)
	$(BIN)/tracker synth demo --record recordings/demo.mcap --force --zstd-level 19

clean:
	rm -rf $(VENV) .pytest_cache
