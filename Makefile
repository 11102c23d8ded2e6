# Everything the project needs is installed from its own files into .venv.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: setup demo test lint bench clean baselines browser render

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip >/dev/null
	$(BIN)/pip install -e ".[dev]"
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)            ## set up, then run the main job on the bundled example
	$(BIN)/mesp demo

test: $(STAMP)            ## set up, then run the whole test suite
	@$(MAKE) --no-print-directory baselines || \
		echo "make baselines failed: the PrusaSlicer baseline tests will skip"
	@$(MAKE) --no-print-directory browser || \
		echo "make browser failed: the console's browser tests will skip"
	@$(MAKE) --no-print-directory render || \
		echo "make render failed: the twin's offscreen pictures and videos will skip"
	$(BIN)/python -m pytest -q

# PrusaSlicer, the commercial planar slicer of `mesp inspect DIR --baseline prusaslicer`.
baselines:                ## install prusa-slicer when it is missing (Debian/Ubuntu, as root)
	@if command -v prusa-slicer >/dev/null 2>&1; then \
		echo "prusa-slicer: $$(command -v prusa-slicer)"; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		export DEBIAN_FRONTEND=noninteractive; \
		apt-get install -y --no-install-recommends prusa-slicer || \
			{ apt-get update && apt-get install -y --no-install-recommends prusa-slicer; }; \
	else \
		echo "prusa-slicer is missing: sudo apt-get install prusa-slicer (until then the PrusaSlicer baseline tests skip)"; \
	fi

# Chromium and its WebDriver, for the web console's browser tests (tests/mesp_cell/web).
browser:                  ## install chromium + chromium-driver when missing (Debian, as root)
	@if command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; then \
		echo "chromium: $$(command -v chromium)"; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		export DEBIAN_FRONTEND=noninteractive; \
		apt-get install -y --no-install-recommends chromium chromium-driver || \
			{ apt-get update && apt-get install -y --no-install-recommends chromium chromium-driver; }; \
	else \
		echo "chromium is missing: sudo apt-get install chromium chromium-driver (until then the browser tests skip)"; \
	fi

# Offscreen OpenGL for MuJoCo (EGL, else OSMesa): dry-run videos, the console's twin view.
render:                   ## install libegl1 + libosmesa6 when missing (Debian, as root)
	@if ldconfig -p | grep -q 'libEGL.so.1' && ldconfig -p | grep -q 'libOSMesa.so'; then \
		echo "offscreen GL: EGL and OSMesa present"; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		export DEBIAN_FRONTEND=noninteractive; \
		apt-get install -y --no-install-recommends libegl1 libegl-mesa0 libosmesa6 || \
			{ apt-get update && apt-get install -y --no-install-recommends libegl1 libegl-mesa0 libosmesa6; }; \
	else \
		echo "offscreen GL is missing: sudo apt-get install libegl1 libegl-mesa0 libosmesa6"; \
	fi

lint: $(STAMP)
	$(BIN)/ruff check core slicer planner sim mesp_cell tests bench examples docs
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python bench/run.py

clean:
	rm -rf $(VENV) build *.egg-info
