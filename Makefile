# Two commands set up everything on a fresh machine:
#   make train  install into .venv and train CRLLK-D from the camera on small_loop (about 25
#               minutes on 2 cores); the run lands in runs/small_loop/crllk-discrete-pixels-seed0
#   make test   install into .venv and run the test suite
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export MUJOCO_GL ?= egl
export PIP_DISABLE_PIP_VERSION_CHECK := 1

TRAIN_ARGS ?=

.PHONY: install train demo test test-slow lint pictures clean

install: $(STAMP)

$(STAMP): pyproject.toml
	bash scripts/install-egl.sh
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip 2>&1 | grep -v "is ignored" || true
	$(PY) -m pip install -q -e ".[dev]" 2>&1 | grep -v -e "is ignored" -e "Warning" -e "!!" -e "\*\*\*" || true
	$(PY) -c "import crllk, torch, torchrl, dm_control, rerun" 
	touch $(STAMP)

train: $(STAMP)
	$(PY) -m crllk.train resume=true $(TRAIN_ARGS)

demo: $(STAMP)
	$(PY) -m crllk.demo

pictures: $(STAMP)
	$(PY) -m crllk.pictures

test: $(STAMP)
	$(PY) -m pytest -q

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

lint: $(STAMP)
	$(VENV)/bin/ruff check .

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
