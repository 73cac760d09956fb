# The add-on in a real Blender window under Xvfb, driven as a person would (docs/ui-testing.md).
# Included from the main Makefile (`include mk/ui.mk`). Needs only Debian packages, not .venv:
# the driver runs on Debian's python3 with python3-numpy. `make test` runs it (mk/run_tests.py).
#
#   make ui-test        install the packages if missing, run the scenario; out/ui/ (report.json,
#                       screenshots); exit status 0 when every check passed (part of make test)
#   make ui-test-cold   the same with an empty numba cache (timings include the compile)
#   make ui-docs-img    run it and refresh docs/img/ui-*.png
#   make legacy-addon   dist/moebius_addon-legacy.zip for Blender 3.4-4.1 (Install... in
#                       Preferences > Add-ons)

UI_DEBS := blender xvfb xdotool imagemagick python3-numba python3-numpy
UI_PY   ?= /usr/bin/python3
UI_OUT  ?= out/ui
UI_SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: ui-deps ui-test ui-test-cold ui-docs-img legacy-addon

# Idempotent and quiet: apt-get runs only when one of the packages is missing (about 90 MB).
ui-deps:
	@dpkg -s $(UI_DEBS) >/dev/null 2>&1 || { \
	  echo "ui-deps: apt-get install $(UI_DEBS)"; \
	  $(UI_SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(UI_SUDO) apt-get install -y -qq --no-install-recommends \
	    $(UI_DEBS) >/dev/null; }

ui-test: ui-deps
	$(UI_PY) tests/ui/run_ui_test.py --out $(UI_OUT)

ui-test-cold: ui-deps
	$(UI_PY) tests/ui/run_ui_test.py --out $(UI_OUT) --cold

ui-docs-img: ui-deps
	$(UI_PY) tests/ui/run_ui_test.py --out $(UI_OUT) --docs-img docs/img

legacy-addon:
	$(UI_PY) tests/ui/legacy_zip.py dist/moebius_addon-legacy.zip
