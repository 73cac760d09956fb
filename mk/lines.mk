# The Blender lines users run; included from the main Makefile, whose PY, STAMP and
# PYTHON it uses.
#
# Every line has a venv of its own, with its own Python: bpy, the numpy that line runs on,
# pytest, and no numba, which the extension brings as wheels, as it does into a user's Blender.
# The 5.0 line's venv runs every Blender test (tests/blender), the other lines the tests marked
# `lines`, each installing the zip of build/test-repo, which the main venv builds as `make repo`
# would (linux-x64 only). None has scipy, as no Blender has: a path that needs it fails there
# (tests/blender/test_packaging.py checks the venv). The main venv (.venv, with the test extras)
# runs the core suite.
#
#   make test-lines          the `lines` tests on 4.2, 4.5 and 5.2 (part of `make test`)
#   make test-line-4.2       one line
#   make venv-lines          the venvs (.venv-blender-X/, each with a stamp file, as .venv)
#   make bench-first-relax   the first relaxation after installing, and on later starts, on
#                            every line (docs/blender.md, Install)

# bpy from PyPI, its Python, and numpy (the bpy wheels bundle none): 1.26.4 on the Python 3.11
# lines (bpy 4.5 and 5.0 ask for numpy >= 1.26, < 2, bpy 4.2 for any; one numpy for the three);
# 2.3.4 on 5.2, inside bpy 5.2.3's >= 2.2, < 3 and numba 0.68's < 2.6 (Blender's own library
# build lists numpy 2.3.4 in a 2026 copy of its versions.cmake).
BPY_5.0   := 5.0.1
PYV_5.0   := 3.11
NUMPY_5.0 := 1.26.4
BPY_4.2   := 4.2.23
PYV_4.2   := 3.11
NUMPY_4.2 := 1.26.4
BPY_4.5   := 4.5.15
PYV_4.5   := 3.11
NUMPY_4.5 := 1.26.4
BPY_5.2   := 5.2.3
PYV_5.2   := 3.13
NUMPY_5.2 := 2.3.4
LINES     := 4.2 4.5 5.2
#: the venvs: the 5.0 line's (every Blender test) and the LINES'
BLENDER_VENVS := 5.0 $(LINES)

# Python 3.13 for bpy 5.2: on PATH, else pyenv's (whose shim fails while another version is the
# global one). PYTHON (3.11) comes from the main Makefile.
PYTHON313 ?= $(shell for p in python3.13 "$${PYENV_ROOT:-$$HOME/.pyenv}"/versions/3.13*/bin/python3.13; do \
	"$$p" -c 'import sys; assert sys.version_info[:2] == (3, 13); print(sys.executable)' \
	2>/dev/null && break; done)
PYTHON_3.11 = $(PYTHON)
PYTHON_3.13 = $(PYTHON313)
PYVAR_3.11  := PYTHON
PYVAR_3.13  := PYTHON313

comma       := ,
TEST_REPO   := build/test-repo
LINE_STAMPS := $(foreach l,$(BLENDER_VENVS),.venv-blender-$(l)/.installed)
# what goes into the zip (directories too: their times change when a file is added or removed)
EXT_SOURCES := blender_manifest.toml mk/build_extension.py $(shell find moebius_addon \
	-name __pycache__ -prune -o -print)

.PHONY: venv-lines test-lines bench-first-relax

venv-lines: $(LINE_STAMPS)

.venv-blender-%/.installed: mk/lines.mk
	@test -n "$(BPY_$*)" || { echo "no Blender line '$*'; the lines are $(LINES)"; exit 1; }
	@"$(PYTHON_$(PYV_$*))" -c 'import sys; sys.exit(sys.version_info[:2] != ($(subst .,$(comma) ,$(PYV_$*))))' \
	  2>/dev/null || { echo "Blender $* (bpy $(BPY_$*)) needs Python $(PYV_$*), which was not" \
	  "found. Install it (pyenv install $(PYV_$*), apt-get install python$(PYV_$*)-venv or uv python" \
	  "install $(PYV_$*)), or set $(PYVAR_$(PYV_$*))=/path/to/python$(PYV_$*)."; exit 1; }
	test -x .venv-blender-$*/bin/python || "$(PYTHON_$(PYV_$*))" -m venv .venv-blender-$*
	.venv-blender-$*/bin/python -m pip install -q bpy==$(BPY_$*) numpy==$(NUMPY_$*) 'pytest>=8'
	touch $@

# The repository the tests install from, built by the main venv as `make repo` builds dist/repo,
# its zip with the kernel cache of both Pythons compiled in Blender venvs (3.11: the 5.0 venv's,
# 3.13: the 5.2 venv's; mk/build_extension.py).
$(TEST_REPO)/index.json: $(STAMP) $(EXT_SOURCES) .venv-blender-5.0/.installed \
	  .venv-blender-5.2/.installed
	$(PY) mk/build_extension.py --repo --platforms linux-x64 --out $(TEST_REPO) \
	  --kernel-cache 3.11=.venv-blender-5.0/bin/python \
	  --kernel-cache 3.13=.venv-blender-5.2/bin/python

# The `lines` tests on one line's venv ($(1): the venv).
LINE_PYTEST = MOEBIUS_TEST_REPO=$(TEST_REPO) $(1)/bin/python -m pytest -q -m "lines and not slow" \
	tests/blender

# The `lines` tests on every line of LINES, each timed; every line runs even when one before it
# failed, and the status is 1 then (a shell fragment for the recipes of test-lines and test).
RUN_LINES = for line in $(LINES); do t=$$(date +%s); \
	  $(call LINE_PYTEST,.venv-blender-$$line) || status=1; \
	  echo "[time] Blender $$line: $$(( $$(date +%s) - t )) s"; done

test-line-%: .venv-blender-%/.installed $(TEST_REPO)/index.json
	$(call LINE_PYTEST,.venv-blender-$*)


test-lines: $(TEST_REPO)/index.json $(LINE_STAMPS)
	@status=0; $(RUN_LINES); exit $$status

bench-first-relax: $(TEST_REPO)/index.json $(STAMP) $(LINE_STAMPS)
	@for venv in $(foreach l,$(BLENDER_VENVS),.venv-blender-$(l)); do \
	  $$venv/bin/python bench/first_relax.py --repo $(TEST_REPO) --update; done
