"""A Blender session of a user who adds the extension's repository (test_repo.py runs it).

    python repo_client.py add URL       add URL as a Remote Repository, sync, install
                                        moebius_addon from it
    python repo_client.py update URL    a later session: sync, count the updates offered,
                                        install them

Run in a fresh process with ``BLENDER_USER_RESOURCES`` set, the same for both. Blender would
read the repository and the enabled add-on of the first session from the saved preferences;
the ``bpy`` module reads none as it starts (and bpy 4.2.23 crashed loading them afterwards with
``wm.read_userpref``: "'bl_ext' is not a package"), so the later session adds the repository
again under the same module name, hence the same directory with the installed add-on, and
enables the add-on. Prints one line of JSON, what the session saw.
"""

import json
import os
import sys
import tomllib
from pathlib import Path

import bpy

REPO_MODULE = "moebius"  # the repository's module name: the add-on is bl_ext.moebius.moebius_addon
PKG = "moebius_addon"
ADDON = f"bl_ext.{REPO_MODULE}.{PKG}"


def installed_version(repo) -> str | None:
    manifest = Path(repo.directory) / PKG / "blender_manifest.toml"
    return tomllib.loads(manifest.read_text())["version"] if manifest.exists() else None


def main(action: str, url: str) -> int:
    prefs = bpy.context.preferences
    # installing needs *Allow Online Access*, even from a file:// URL (package_install.poll)
    prefs.system.use_online_access = True
    repos = prefs.extensions.repos
    repo = repos.new(name="Möbius", module=REPO_MODULE, remote_url=url)
    index = list(repos).index(repo)
    seen = {}
    if action == "update":
        seen["version before"] = installed_version(repo)
        seen["enable"] = sorted(bpy.ops.preferences.addon_enable(module=ADDON))
    seen["sync"] = sorted(bpy.ops.extensions.repo_sync(repo_index=index))
    if action == "add":
        seen["install"] = sorted(bpy.ops.extensions.package_install(
            repo_index=index, pkg_id=PKG, enable_on_install=True))
    else:
        import bl_pkg  # Blender's extensions add-on: what its Preferences page counts

        seen["updates offered"] = bl_pkg.repo_stats_calc_outdated_for_repo_directory(
            bl_pkg.repo_cache_store_ensure(), repo.directory)
        seen["upgrade"] = sorted(bpy.ops.extensions.package_upgrade_all())
    seen["version"] = installed_version(repo)
    seen["enabled"] = ADDON in prefs.addons
    seen["operators"] = hasattr(bpy.ops.moebius, "relax") and hasattr(bpy.types.Scene, "moebius")
    print(json.dumps(seen), flush=True)
    if bpy.app.version < (4, 5):
        # bpy 4.2.23 (the module) crashed at exit after an add-on was enabled a second time in
        # the process, as an update does: C++ static destructors freed a SpaceType's Python
        # panel class after Python had finalized (bpy_class_free, PyGILState_Ensure). Blender
        # itself frees space types before Python; this session leaves without the destructors.
        os._exit(0)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
