# Two commands on a fresh Debian machine with Python 3.11:  make demo  /  make test
# Both create .venv and install everything (system libraries too, when run as root).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out/demo
STAMP  := $(VENV)/.installed

.PHONY: demo test lint bench sysdeps clean

$(STAMP): pyproject.toml
	@bash tools/sysdeps.sh
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "graphnav needs Python >= 3.11, this is " + sys.version' \
		|| { echo "error: install Python 3.11+ (Debian: apt-get install python3 python3-venv)"; exit 1; }
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV) \
		|| { echo "error: python venv failed; on Debian run: apt-get update && apt-get install -y python3-venv"; exit 1; }
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

sysdeps:
	@bash tools/sysdeps.sh

demo: $(STAMP)
	$(BIN)/graphnav demo --out $(OUT)

test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider

lint: $(STAMP)
	$(BIN)/ruff check graphnav factors tests benchmarks examples

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) out
