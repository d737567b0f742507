# Two commands set up everything on a fresh machine:
#   make demo   install into .venv, drive the scripted lane follower on every map, write pictures
#   make test   install into .venv and run the test suite
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export MUJOCO_GL ?= egl
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: install demo test test-slow lint pictures clean

install: $(STAMP)

$(STAMP): pyproject.toml
	bash scripts/install-egl.sh
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip 2>&1 | grep -v "is ignored" || true
	$(PY) -m pip install -q -e ".[dev]" 2>&1 | grep -v -e "is ignored" -e "Warning" -e "!!" -e "\*\*\*" || true
	$(PY) -c "import crllk, torch, torchrl, dm_control, rerun" 
	touch $(STAMP)

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
