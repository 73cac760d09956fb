"""The UI test runs a real Blender window; it is opt-in (see test_ui.py, docs/ui-testing.md)."""


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "ui: drives Debian's Blender under Xvfb with xdotool (opt-in: "
                   "MOEBIUS_UI_TEST=1, or `make ui-test`)")
