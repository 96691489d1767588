# Two commands on a fresh machine:  make demo   and   make test
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO   := out/demo

.PHONY: demo test docs setup system-deps bench regression clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,realsense,docs]'
	touch $(STAMP)

setup: system-deps $(STAMP)

# System packages (libusb for pyrealsense2, chromium + its driver for the browser test): installed with
# apt-get when run as root, otherwise one line saying which command installs them.
system-deps:
	@PYTHON=$(PYTHON) bash tools/system_deps.sh

test: system-deps $(STAMP)
	$(BIN)/python -m pytest -q

# The main job on data the project makes: simulate a wind-excited branch with a hidden propagation
# delay and render it as video, then track -> analyze -> diagnose it, with figures and a Rerun recording.
demo: system-deps $(STAMP)
	rm -rf $(DEMO)
	$(BIN)/rce simulate --seed 0 --frames 450 --effect delay --video --out $(DEMO)/simulation
	$(BIN)/rce run $(DEMO)/simulation/video.mp4 $(DEMO)/simulation/annotations.json \
		$(DEMO)/simulation/graph.json --out $(DEMO)/run --rerun $(DEMO)/run/recording.rrd
	@echo
	@echo "demo outputs:    $(CURDIR)/$(DEMO)/run/ (tables, report.json, diagnosis.json, figures/)"
	@echo "ground truth:    $(CURDIR)/$(DEMO)/simulation/truth.json"
	@echo "Rerun recording: $(CURDIR)/$(DEMO)/run/recording.rrd  (open with: $(BIN)/rerun $(DEMO)/run/recording.rrd)"

# The documentation site, warnings as errors, into site/ (open site/index.html); it runs the tutorial
# notebooks and the commands whose output and figures the pages show (tests/test_docs.py builds it too).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict

regression: $(STAMP)
	$(BIN)/python regression/run_regression.py ../shared/data/plant_2

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_analyze.py

clean:
	rm -rf out site .pytest_cache
