# Two commands on a fresh clone:  `make demo`  and  `make test`.
# Each creates .venv (Python 3.11, as bpy==5.0.1 requires) and installs what it needs; `make test`
# also creates a venv per Blender line (mk/lines.mk; bpy 5.2 needs Python 3.13).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: venv test test-all demo bench lint clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else "bpy==5.0.1 needs Python 3.11; set PYTHON=/path/to/python3.11")'
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test,blender,build]'
	touch $@

include mk/lines.mk

# CI runs this (via .ci/run): the whole suite except runs marked slow: the core suite in .venv,
# every Blender test on Blender 5.0 and those marked `lines` on Blender 4.2, 4.5 and 5.2, each in
# a venv with what Blender's Python has and no more (mk/lines.mk), and the add-on in a
# real Blender window (mk/ui.mk: Debian's Blender 3.4 under Xvfb, the packages installed with
# apt-get when missing), in two streams side by side (mk/run_tests.py: most parts use one core).
# Every part runs even when one before it failed; the status is the worst.
test: $(STAMP) $(LINE_STAMPS)
	@$(PY) mk/run_tests.py --python $(PY) --repo $(TEST_REPO) --lines $(LINES) --make "$(MAKE)"

test-all: $(STAMP) $(TEST_REPO)/index.json
	MOEBIUS_TEST_REPO=$(TEST_REPO) $(PY) -m pytest -q

lint: $(STAMP)
	$(PY) -m ruff check moebius_addon tests bench mk

demo: $(STAMP)
	$(PY) bench/demo_blender.py --out out

bench: $(STAMP)
	$(PY) bench/core_bench.py

clean:
	rm -rf $(VENV) .venv-blender-* out dist build

include mk/blender.mk
include mk/ui.mk
