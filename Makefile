# Two commands set up everything on a fresh machine:
#   make train  install into .venv and train CRLLK-D from the camera on small_loop (about 10
#               minutes on 2 cores, its final evaluation included); the run lands in
#               runs/small_loop/crllk-discrete-pixels-seed0
#   make test   install into .venv and run the test suite (the documentation site built and
#               checked in a headless chromium included)
#   make docs   build the documentation site into site/ (strict); make docs-serve serves it
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
CLUSTER_STAMP := $(VENV)/.installed-cluster
export MUJOCO_GL ?= egl
export PIP_DISABLE_PIP_VERSION_CHECK := 1
export NO_MKDOCS_2_WARNING := 1

TRAIN_ARGS ?=
# pytest workers for `make test` (pytest-xdist; `auto` is one per core)
TEST_JOBS ?= auto

.PHONY: install install-cluster peers train demo test test-slow lint pictures viewer-pictures docs \
	docs-serve docs-pictures clean

install: $(STAMP)

$(STAMP): pyproject.toml scripts/install-egl.sh scripts/install-chromium.sh
	bash scripts/install-egl.sh
	bash scripts/install-chromium.sh
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip 2>&1 | grep -v "is ignored" || true
	$(PY) -m pip install -q -e ".[dev,docs]" 2>&1 | grep -v -e "is ignored" -e "Warning" -e "!!" -e "\*\*\*" || true
	$(PY) -c "import crllk, torch, torchrl, dm_control, rerun, mkdocs, material, mkdocstrings_handlers.python, playwright" 
	touch $(STAMP)

# the `cluster` extra (the submitit and Ray launchers, Ray itself: heavy), for the slow tests
install-cluster: $(CLUSTER_STAMP)

$(CLUSTER_STAMP): $(STAMP)
	$(PY) -m pip install -q -e ".[dev,docs,cluster]" 2>&1 | grep -v -e "is ignored" -e "Warning" -e "!!" -e "\*\*\*" || true
	$(PY) -c "import hydra_plugins.hydra_ray_launcher, hydra_plugins.hydra_submitit_launcher, ray"
	touch $(CLUSTER_STAMP)

# OmniSafe (a peer library: python -m crllk.experiments peers --obs state) in its own Python
# 3.10 environment, .venv-omnisafe (its pins cannot share .venv; about 5 GB with torch's CUDA build)
PEERS_PYTHON ?= python3.10
PEERS_VENV := .venv-omnisafe
PEERS_STAMP := $(PEERS_VENV)/.installed

peers: $(PEERS_STAMP)

$(PEERS_STAMP): peers/omnisafe/requirements.txt $(STAMP)
	test -x $(PEERS_VENV)/bin/python || $(PEERS_PYTHON) -m venv $(PEERS_VENV)
	$(PEERS_VENV)/bin/python -m pip install -q -r peers/omnisafe/requirements.txt 2>&1 | grep -v "is ignored" || true
	$(PEERS_VENV)/bin/python -c "import omnisafe"
	touch $(PEERS_STAMP)

train: $(STAMP)
	$(PY) -m crllk.train resume=true $(TRAIN_ARGS)

demo: $(STAMP)
	$(PY) -m crllk.demo

pictures: $(STAMP)
	$(PY) -m crllk.pictures

# the README's screenshots of the real rerun viewer, taken headless (about 3 minutes on 2 cores):
# a follower recording on obstacle_loop at 9 s, one on traffic_loop at 2 s, and a short training
# run's live view at its end
VIEWER_RECORDING := outputs/recordings/obstacle_loop_follower.rrd
TRAFFIC_RECORDING := outputs/recordings/traffic_loop_follower.rrd
viewer-pictures: $(STAMP)
	$(PY) -m crllk.record --task obstacle_loop --episodes 3 --horizon 150 --seed 1 --out $(VIEWER_RECORDING)
	$(PY) -m crllk.screenshots $(VIEWER_RECORDING) --out docs/images --prefix viewer_recording --times 9
	$(PY) -m crllk.record --task traffic_loop --episodes 1 --horizon 240 --seed 3 --out $(TRAFFIC_RECORDING)
	$(PY) -m crllk.screenshots $(TRAFFIC_RECORDING) --out docs/images --prefix viewer_traffic --times 2
	$(PY) -m crllk.screenshots --out docs/images --prefix viewer_live_training --train \
		task=obstacle_loop obs=state seed=0 total_frames=40960 record_every=10 eval.final=false

# the documentation site: strict (a broken link, anchor or include, a page missing from the
# navigation or a docstring the API reference cannot read fails the build)
docs: $(STAMP)
	$(PY) -m mkdocs build --strict

docs-serve: $(STAMP)
	$(PY) -m mkdocs serve --strict -a 127.0.0.1:8000

# the screenshots of the site's home and results pages, in the headless chromium
docs-pictures: docs
	$(PY) scripts/site_browser.py site --pictures docs/images

test: $(STAMP)
	$(PY) -m pytest -q -n $(TEST_JOBS)

test-slow: $(CLUSTER_STAMP)
	$(PY) -m pytest -q -m slow

lint: $(STAMP)
	$(VENV)/bin/ruff check .

clean:
	rm -rf $(VENV) .pytest_cache build site *.egg-info
