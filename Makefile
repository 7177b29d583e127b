# Two entry points (README): `make repro` installs and runs the pipeline, `make test` installs and runs the tests.
SHELL := /bin/bash
# The first Python 3.12 that runs: pyenv's install (its shim may not be active), else python3.12 on PATH.
PYTHON ?= $(shell for p in $$HOME/.pyenv/versions/3.12*/bin/python3.12 python3.12; do \
	"$$p" -c 'import sys; assert sys.version_info[:2] == (3, 12)' 2>/dev/null && { echo "$$p"; break; }; done)
VENV := .venv
BIN := $(VENV)/bin
# dvc runs each stage's `mor ...` command in a shell: it must find this checkout's environment first.
export PATH := $(abspath $(BIN)):$(PATH)
export MUJOCO_GL ?= egl
export HF_HUB_OFFLINE := 1
export HF_DATASETS_OFFLINE := 1
export DVC_NO_ANALYTICS := 1
export TQDM_MININTERVAL ?= 5

.PHONY: install test repro bench clean

$(BIN)/.installed: pyproject.toml
	@test -n "$(PYTHON)" || { echo "error: Python 3.12 not found; install it (pyenv install 3.12) or run make PYTHON=/path/to/python3.12" >&2; exit 1; }
	@ldconfig -p | grep -q 'libEGL.so.1' || { echo "installing Mesa EGL for headless rendering"; apt-get update -qq && apt-get install -y -qq libegl1 libgl1-mesa-dri >/dev/null; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev,bench]'
	touch $@

install: $(BIN)/.installed

test: install
	$(BIN)/pytest -n 2 --dist worksteal -m "pipeline or not pipeline"   # every test, the tiny dvc repro included (pyproject.toml)

repro: install
	$(BIN)/dvc repro

bench: install
	$(BIN)/mor bench sim

clean:
	rm -rf $(VENV) .pytest_cache
