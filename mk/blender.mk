# Blender extension targets; included from the main Makefile (`include mk/blender.mk`).
# Uses PY and STAMP from the main Makefile.

.PHONY: extension extension-linux test-blender demo-core

# Per-platform extension zips in dist/ (downloads the pinned numba/llvmlite wheels into wheels/).
extension: $(STAMP)
	$(PY) mk/build_extension.py --out dist

extension-linux: $(STAMP)
	$(PY) mk/build_extension.py --platforms linux-x64 --out dist

# Only the Blender tests (installs the linux-x64 zip into a throw-away user directory).
test-blender: $(STAMP)
	$(PY) -m pytest -q -m "not slow" tests/blender

# The core-only demo (numpy + matplotlib, no Blender); `make demo` is the Blender one.
demo-core: $(STAMP)
	$(PY) bench/demo_core.py --out out
