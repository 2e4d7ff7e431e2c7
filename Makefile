# rotstar-mrcal: set-up, tests, demo and benchmark.
# Everything installs itself: a Python >= 3.12 interpreter is found (PATH or pyenv),
# uv is bootstrapped from PyPI if missing, the locked environment goes to .venv,
# and Debian packages (mrgingham) are installed with apt-get when absent.

SHELL := /bin/bash
.DEFAULT_GOAL := help
export UV_PYTHON_DOWNLOADS := never
export UV_PROJECT_ENVIRONMENT := $(CURDIR)/.venv

VENV_BIN := $(CURDIR)/.venv/bin
# mrcal's tools and ours from the venv; gnuplot from .tools/gnuplot (a link to Debian's, which reads
# PNG images: the one mrcal's wheel puts in the venv's bin cannot, and mrcal-show-residuals-board-observation
# needs it to draw a board over its image)
GNUPLOT_BIN := $(CURDIR)/.tools/gnuplot
RUN := PATH="$(GNUPLOT_BIN):$(VENV_BIN):$$PATH"
PYTEST_ARGS ?=
# the tests run in TEST_JOBS processes (pytest-xdist), a test file per process so that its fixtures are made once
TEST_JOBS ?= auto
XDIST := -n $(TEST_JOBS) --dist loadfile
DEMO_DIR ?= demo-out
STEREO_DIR ?= stereo-out
BENCH_ARGS ?=
BLURMAP_DIR ?= blur-map-out

# The first candidate that really runs and is >= 3.12 (pyenv shims can exist and fail).
PYTHON := $(shell for c in python3.13 python3.12 $$(ls -d $$(pyenv root 2>/dev/null)/versions/3.1[2-9]*/bin/python3 2>/dev/null | sort -rV) /usr/bin/python3.13 /usr/bin/python3.12 python3; do \
	  if "$$c" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1; then command -v "$$c" || echo "$$c"; break; fi; done)

# uv on PATH only if it runs (a pyenv shim named uv can exist for another Python version and fail).
UV := $(shell if uv --version >/dev/null 2>&1; then command -v uv; elif [ -x $(CURDIR)/.tools/bin/uv ]; then echo $(CURDIR)/.tools/bin/uv; fi)
ifeq ($(UV),)
UV := $(CURDIR)/.tools/bin/uv
endif

.PHONY: help setup test test-slow demo stereo bench calib-bench coverage-bench capture-calib-bench display-bench glass-bench blur-map-doc pip-check clean check-python system-deps python

help:
	@echo "make demo   - pattern, simulated D435 capture, detection, mrcal calibration (all set-up included)"
	@echo "make test   - run the test suite (all set-up included)"
	@echo "make test-slow - the long end-to-end tests that make test leaves out"
	@echo "make stereo - simulated D435 stereo pair: joint calibrations vs the truth, cross-validation, depth error at 0.5/1/2 m"
	@echo "make bench  - accuracy and speed against OpenCV and mrgingham, partial views against ChArUco, each method's failure modes, then calib-bench, coverage-bench, display-bench and capture-calib-bench"
	@echo "make calib-bench - rotstar-calibrate's default model vs rotstar-detect's printed command (12/20/40 poses); a cover glass (0-1.5 mm) plain vs corrected, exact and rendered, one camera and the stereo pair"
	@echo "make coverage-bench - mrcal's uncertainty with and without boards hanging over the imager's edges"
	@echo "make display-bench - a display showing the frames like a real monitor (per-frame maps): poses kept, maps, calibration vs a clean display (20 D435 poses)"
	@echo "make capture-calib-bench - seconds at the screen: today's 25 s capture vs the short one, calibrated vs the truth (about 7 min)"
	@echo "make glass-bench - a screen's cover glass (0-1.5 mm): plain calibration vs rotstar-calibrate's correction (20/40 poses)"
	@echo "make blur-map-doc - doc/img/blur-map.png: rotstar-detect --blur-map on a simulated D435 with strong coma; then --refine psf-sim's time per pose against the default (doc/blur-map.md)"
	@echo "make pip-check   - install with plain pip (scripts/pip_install.sh) into a fresh venv and check it"

python: check-python  ## the Python >= 3.12 the set-up uses (the plain-pip path of README.md uses it too)
	@echo $(PYTHON)

check-python:
	@if [ -z "$(PYTHON)" ]; then \
	  echo "error: no working Python >= 3.12 found (tried python3.13, python3.12, pyenv versions, python3); mrcal's wheels need CPython >= 3.12" >&2; exit 1; fi

$(CURDIR)/.tools/bin/uv: | check-python
	@echo "installing uv into .tools (from PyPI)" >&2
	$(PYTHON) -m venv $(CURDIR)/.tools
	$(CURDIR)/.tools/bin/pip install -q uv

system-deps:
	@missing=""; command -v mrgingham >/dev/null || missing="$$missing mrgingham"; \
	[ -x /usr/bin/chromium ] || missing="$$missing chromium"; \
	/usr/bin/gnuplot -e 'show version long' 2>&1 | grep -q +GD_PNG || missing="$$missing gnuplot-nox"; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing" >&2; \
	  if [ "$$(id -u)" = 0 ]; then (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing) >&2 || echo "warning: could not install$$missing; the tests that need them will be skipped" >&2; \
	  else echo "warning: not root, cannot apt-get install$$missing; the tests that need them will be skipped" >&2; fi; \
	fi; \
	if [ -x /usr/bin/gnuplot ]; then mkdir -p $(GNUPLOT_BIN) && ln -sf /usr/bin/gnuplot $(GNUPLOT_BIN)/gnuplot; fi

# Bytecode compiled at install time: with PYTHONDONTWRITEBYTECODE set (or a read-only venv) every
# command would otherwise compile scipy & co. from source at each start (measured 0.5 s of rotstar-detect's 0.95 s).
.venv/.synced: pyproject.toml uv.lock $(UV) | check-python
	$(UV) sync --frozen --compile-bytecode --python $(PYTHON)
	@touch $@

setup: .venv/.synced system-deps
	@$(VENV_BIN)/python -m compileall -q rotstar_mrcal >/dev/null  # the project's own modules, as above

test: setup
	$(RUN) $(VENV_BIN)/python -m pytest -q $(XDIST) $(PYTEST_ARGS)

# the long end-to-end runs that make test leaves out (marked slow): whole benchmarks in small, every
# player check in chromium, the report of a simulated run, the plain-pip install (make pip-check)
test-slow: setup
	$(RUN) $(VENV_BIN)/python -m pytest -q $(XDIST) -m slow --ignore=tests/cli/test_pip_install.py $(PYTEST_ARGS)

demo: setup
	$(RUN) $(VENV_BIN)/python scripts/demo.py --out $(DEMO_DIR)

# writes its tables into doc/validation.md (stereo:tables) and README.md (stereo:headline)
stereo: setup
	$(RUN) $(VENV_BIN)/python scripts/stereo.py --out $(STEREO_DIR)

bench: setup
	$(RUN) $(VENV_BIN)/python scripts/bench.py $(BENCH_ARGS)
	$(MAKE) calib-bench
	$(MAKE) coverage-bench
	$(MAKE) display-bench
	$(MAKE) capture-calib-bench

# writes its tables into doc/validation.md (between the calib-bench and calib-bench-glass markers)
calib-bench: setup
	$(RUN) $(VENV_BIN)/python scripts/calib_bench.py --work calib-bench-out --doc

# writes its table into doc/uncertainty.md (between the coverage-bench markers) and doc/img/coverage/
coverage-bench: setup
	$(RUN) $(VENV_BIN)/python scripts/coverage_bench.py --work coverage-bench-out --doc

# writes its table into doc/detector.md (between the display-bench markers); renders 2 x 21 D435 poses (minutes)
display-bench: setup
	$(RUN) $(VENV_BIN)/python scripts/display_bench.py --poses 20 --work display-bench-out --doc

# writes its table into doc/capture.md (between the capture-calib-bench markers); about 7 min on 2 cores
capture-calib-bench: setup
	$(RUN) $(VENV_BIN)/python scripts/capture_calib_bench.py --work capture-calib-bench-out --doc

# writes its table into doc/simulator.md (between the glass-bench markers); about 1.5 min on 2 cores
glass-bench: setup
	$(RUN) $(VENV_BIN)/python scripts/glass_bench.py --work glass-bench-out --doc

# the picture of doc/blur-map.md: 8 near poses through 2.5 waves of coma (rotating-star frames only)
blur-map-doc: setup
	$(RUN) rotstar-simulate --out $(BLURMAP_DIR)/seq --camera d435 --seidel coma=2.5,focus=0.3 --poses 8 --no-identity \
	    --distance 0.18 0.26 --seed 1 --jobs 2 --force
	$(RUN) rotstar-detect $(BLURMAP_DIR)/seq --blur-map $(BLURMAP_DIR) -o $(BLURMAP_DIR)/corners.vnl --jobs 2
	cp $(BLURMAP_DIR)/blur_map.png doc/img/blur-map.png
	$(RUN) $(VENV_BIN)/python scripts/psf_time_bench.py $(BLURMAP_DIR)/seq --runs 5 --doc doc/blur-map.md

pip-check: check-python
	PYTHON=$(PYTHON) $(VENV_BIN)/python -m pytest -q -s -m slow tests/cli/test_pip_install.py

clean:
	rm -rf .venv .tools $(DEMO_DIR) $(STEREO_DIR) .pytest_cache calib-bench-out coverage-bench-out capture-calib-bench-out display-bench-out glass-bench-out $(BLURMAP_DIR)
