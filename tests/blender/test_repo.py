"""A repository users can add: the static repository of ``make repo`` added to Blender
as a Remote Repository, the extension installed through it, then a newer version published to
it, offered as an update in a later session and installed.

Each Blender session is a process of its own (tests/blender/repo_client.py) with a user
directory of its own, as a user's Blender; the host is a directory served by file:// URL.
"""

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from bpy_helpers import PYTHON, ROOT, build_extension

CLIENT = Path(__file__).with_name("repo_client.py")


def _session(args, user_dir):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user_dir))
    proc = subprocess.run([sys.executable, str(CLIENT), *args], env=env, capture_output=True,
                          text=True, timeout=600)
    said = [line for line in proc.stdout.splitlines() if not line.startswith("PROGRESS")]
    assert proc.returncode == 0, "\n".join(said[-30:]) + proc.stderr[-3000:]
    return json.loads(said[-1])


def _next_version(version: str) -> str:
    *head, patch = version.split(".")
    return ".".join([*head, str(int(patch) + 1)])


@pytest.mark.lines
def test_add_repository_install_and_update(repo_index, tmp_path):
    version = tomllib.loads((ROOT / "blender_manifest.toml").read_text())["version"]
    host = tmp_path / "host"  # what a static host serves: the zips and index.json
    shutil.copytree(repo_index.parent, host)
    index = json.loads((host / "index.json").read_text())
    (entry,) = index["data"]
    assert (entry["id"], entry["version"], entry["platforms"]) == (
        "moebius_addon", version, ["linux-x64"])
    assert entry["archive_url"].startswith("./")  # relative: the host's URL does not matter
    assert PYTHON in entry["python_versions"]

    user, url = tmp_path / "user", (host / "index.json").as_uri()
    first = _session(["add", url], user)
    assert first == {"sync": ["FINISHED"], "install": ["FINISHED"], "version": version,
                     "enabled": True, "operators": True}

    # a release: the newer zip (this venv's blender_ext.py, this Python's wheels) replaces the
    # old one on the host, and index.json is written again
    newer = _next_version(version)
    build_extension().build_repo(host, ["linux-x64"], [PYTHON], version=newer)
    assert [p.name for p in host.glob("*.zip")] == [f"moebius_addon-{newer}-linux_x64.zip"]
    with zipfile.ZipFile(next(host.glob("*.zip"))) as z:
        assert f'version = "{newer}"' in z.read("blender_manifest.toml").decode()

    later = _session(["update", url], user)
    assert later == {"version before": version, "enable": ["FINISHED"], "sync": ["FINISHED"],
                     "updates offered": 1, "upgrade": ["FINISHED"], "version": newer,
                     "enabled": True, "operators": True}
