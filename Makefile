# nlosplan set-up and main targets. `make demo` and `make test` each install
# everything they need into .venv first (idempotent; re-runs only when
# pyproject.toml changes).

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.nlosplan-installed
SUDO    = $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: setup system-deps demo test check bench clean

setup: system-deps $(STAMP)

# Mitsuba's CPU variant needs libLLVM >= 16 (Debian 12 ships 15 by default); the deposit kernel a C++ compiler.
system-deps:
	@if ls /usr/lib/*/libLLVM-1[6-9].so /usr/lib/*/libLLVM-2[0-9].so /usr/lib/llvm-1[6-9]/lib/libLLVM*.so* >/dev/null 2>&1; then \
	  echo "libLLVM >= 16 present"; \
	else \
	  echo "installing libllvm19 (Mitsuba CPU variant)"; \
	  $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq libllvm19; \
	fi
	@# a C++ compiler builds the fast simulator's deposit kernel on first use (without one: XLA's scatter-add, ~3x slower)
	@if command -v c++ >/dev/null 2>&1 || command -v g++ >/dev/null 2>&1 || command -v clang++ >/dev/null 2>&1; then \
	  echo "C++ compiler present"; \
	else \
	  echo "installing g++ (the fast simulator's deposit kernel)"; \
	  $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq g++; \
	fi

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	# pinned CPU build of PyTorch first, so nothing pulls the CUDA wheels
	$(BIN)/python -m pip install -q torch==2.13.0
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

# The main job: the least hardware per NLOS task on the DENALI preset (report in nlosplan-out/design).
demo: setup
	$(BIN)/nlosplan design

# Tests marked slow (whole-catalog and end-to-end runs that have faster siblings) run only
# when CI is set (CI=true make test, as .ci/run is called) or with SLOW=1. They run on
# TEST_WORKERS processes (pytest-xdist; default one per core), a test file per worker.
TEST_WORKERS ?= auto
test: setup
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=30 $(if $(or $(CI),$(SLOW)),,-m "not slow")

check: setup
	$(BIN)/nlosplan check

bench: setup
	$(BIN)/nlosplan bench histogram

clean:
	rm -rf $(VENV) nlosplan-out .pytest_cache .hypothesis
