# Blender extension targets; included from the main Makefile (`include mk/blender.mk`).
# Uses PY and STAMP from the main Makefile.

.PHONY: extension extension-linux repo release test-blender demo-core

# The linux-x64 zip carries the kernels compiled for both Pythons it ships wheels for: 3.11 by
# the Blender 5.0 venv when it exists, else the main venv, 3.13 by the Blender 5.2 venv when it
# exists (`make venv-lines`; without it that zip has the 3.11 kernels only, and Blender 5.1+
# compiles on first use, saying so). Either way the build hides scipy from the compiling
# process, as Blender's Python has none (mk/build_extension.py).
KERNEL_CACHE := $(if $(wildcard .venv-blender-5.0/bin/python),--kernel-cache 3.11=.venv-blender-5.0/bin/python) \
	$(if $(wildcard .venv-blender-5.2/bin/python),--kernel-cache 3.13=.venv-blender-5.2/bin/python)

# Per-platform extension zips in dist/ (downloads the pinned numba/llvmlite wheels into wheels/).
extension: $(STAMP)
	$(PY) mk/build_extension.py --out dist $(KERNEL_CACHE)

extension-linux: $(STAMP)
	$(PY) mk/build_extension.py --platforms linux-x64 --out dist $(KERNEL_CACHE)

# A static extension repository in dist/repo: the zip of every platform and index.json (with
# blender_ext.py server-generate), to upload to any static host; users add the URL of its
# index.json as a Remote Repository (docs/blender.md, "A repository users can add").
repo: $(STAMP)
	$(PY) mk/build_extension.py --repo --out dist/repo $(KERNEL_CACHE)

# A release: the versions equal (blender_manifest.toml, pyproject.toml, bl_info) and dated in
# CHANGELOG.md (mk/release.py), then the repository, and its zips copied to dist/ to attach to
# the release. Publishing is then uploading dist/repo (docs/blender.md, "Publishing a release").
release: $(STAMP)
	$(PY) mk/release.py
	$(PY) mk/build_extension.py --repo --out dist/repo $(KERNEL_CACHE)
	cp dist/repo/*.zip dist/
	@echo "release: dist/*.zip and dist/repo/ built from $$(git describe --always --dirty)"

# Only the Blender tests, in the Blender 5.0 venv (installs the linux-x64 zip into a throw-away
# user directory).
test-blender: .venv-blender-5.0/.installed $(TEST_REPO)/index.json
	MOEBIUS_TEST_REPO=$(TEST_REPO) .venv-blender-5.0/bin/python -m pytest -q -m "not slow" \
	  tests/blender

# The core-only demo (numpy + matplotlib, no Blender); `make demo` is the Blender one.
demo-core: $(STAMP)
	$(PY) bench/demo_core.py --out out
