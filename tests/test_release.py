"""Release notes and versions (mk/release.py, which `make release` runs)."""

import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "mk"))
import release  # noqa: E402 - mk/ is not a package

sys.path.pop(0)

CHANGELOG = """# Changelog

## [Unreleased]

### Added
- something

## [0.2.0] - 2027-01-05

## [0.1.0] - 2026-12-01
"""


def test_one_version_in_every_file():
    found = release.versions()
    assert len(set(found.values())) == 1, found


def test_changelog_of_the_repository_is_well_formed():
    (version,) = set(release.versions().values())
    assert release.check_changelog((ROOT / "CHANGELOG.md").read_text(), version,
                                   release=False) == []


@pytest.mark.parametrize(("version", "is_release", "words"), [
    ("0.2.0", True, None),  # the newest dated section: ready
    ("0.2.1", False, None),  # being prepared: no section yet
    ("0.2.1", True, "no section for 0.2.1 as its newest release"),
    ("0.1.0", True, "no section for 0.1.0 as its newest release"),
    ("0.1.5", False, "older than the newest release in CHANGELOG.md, 0.2.0"),
])
def test_a_release_needs_its_dated_section_on_top(version, is_release, words):
    problems = release.check_changelog(CHANGELOG, version, is_release)
    assert problems == [] if words is None else any(words in p for p in problems), problems


@pytest.mark.parametrize(("text", "words"), [
    (CHANGELOG.replace("## [0.2.0] - 2027-01-05", "## [0.2.0]"), "needs a version X.Y.Z and a"),
    (CHANGELOG.replace("## [Unreleased]\n", ""), "must start with '## [Unreleased]'"),
    (CHANGELOG.replace("## [0.1.0] - 2026-12-01", "## [0.3.0] - 2026-12-01"), "newest first"),
    (CHANGELOG.replace("## [0.1.0] - 2026-12-01", "## 0.1.0 (2026-12-01)"), "line 10"),
])
def test_malformed_changelogs_are_named(text, words):
    problems = release.check_changelog(text, "0.2.0", True)
    assert any(words in p for p in problems), problems


def test_differing_versions_are_refused(tmp_path):
    for name in ("blender_manifest.toml", "pyproject.toml", "CHANGELOG.md"):
        shutil.copy(ROOT / name, tmp_path / name)
    (tmp_path / "moebius_addon").mkdir()
    init = (ROOT / "moebius_addon" / "__init__.py").read_text()
    stated = '"version": ({}),'.format(", ".join(release.versions()["pyproject.toml"].split(".")))
    assert init.count(stated) == 1
    (tmp_path / "moebius_addon" / "__init__.py").write_text(
        init.replace(stated, '"version": (9, 9, 9),'))
    assert release.check(tmp_path, release=False) == [
        "the versions differ: blender_manifest.toml {0}, pyproject.toml {0}, "
        "moebius_addon/__init__.py (bl_info) 9.9.9".format(release.versions()["pyproject.toml"])]
