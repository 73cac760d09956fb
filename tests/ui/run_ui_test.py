"""The add-on in a real Blender window, used as a person would: the driver of ``make ui-test``.

Starts Xvfb and Debian's Blender (3.4, a legacy add-on install) with an isolated user
configuration, opens a file with a knotted NURBS curve selected, switches the sidebar to the
Möbius tab (a click on it), and then with xdotool mouse clicks on the buttons:

1. Convert (160 edges, stored in the file), then Relax;
2. while the flow runs: successive screenshots, whose 3D views must differ, and whose status
   bar and panel must differ from the idle ones (status text / iteration counter);
3. Esc (a key press into the window): the run must stop early, with every iterate so far
   keyframed, the start frame equal to the converted curve, the original curve kept hidden;
4. Clear Flow Animation (the start shape comes back), Relax again until it finishes;
5. the energy F-curve in a Graph Editor.

Buttons are found from the panel as drawn: for one frame the harness paints operator buttons
in a marker colour (theme ``wcol_tool.inner``), a screenshot is taken, the colour restored,
and each marked rectangle is told by what Ctrl+C over it copies (an operator button's Python
command, ``bpy.ops.moebius.relax(append=False)``), scrolling the sidebar when a button is out
of view: no order or size of the panel's buttons is assumed. The scene checks run inside
Blender (``harness.py``); the driver only moves the mouse, clicks, types, screenshots and
compares pixels.

Everything lands in ``out/ui/``: numbered screenshots, ``report.json`` (every check, timings),
``blender.log``. Exit status 0 when every check passed.

Usage::

    python tests/ui/run_ui_test.py [--out out/ui] [--docs-img docs/img] [--cold]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from itertools import pairwise
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from legacy_zip import legacy_zip  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
SCREEN = (1600, 1000)
#: Debian packages (binaries checked by name) the test needs; ``make ui-test`` installs them.
TOOLS = {"blender": "blender", "Xvfb": "xvfb", "xdotool": "xdotool", "import": "imagemagick"}
CONVERT = "/usr/bin/convert"  # ImageMagick's (a stand-in may shadow it earlier on PATH)


class UITestError(RuntimeError):
    pass


# ---------------------------------------------------------------------------------------------
# Small helpers

def missing_tools() -> list[str]:
    missing = [pkg for exe, pkg in TOOLS.items() if shutil.which(exe) is None]
    if not Path(CONVERT).exists() and "imagemagick" not in missing:
        missing.append("imagemagick")
    probe = subprocess.run(["dpkg", "-s", "python3-numba"], capture_output=True)
    if probe.returncode != 0:
        missing.append("python3-numba")
    return missing


class Session:
    """Xvfb + Blender + the file protocol to the harness, with screenshot helpers."""

    def __init__(self, out: Path, cold: bool, log) -> None:
        self.out = out
        self.cold = cold
        self.log = log
        self.display = None
        self.xvfb = None
        self.blender = None
        self.seq = 0
        self.blender_args = None
        self.restarted = False  # Xvfb and Blender started again once (find_window)
        self.screenshots_taken = 0
        self.win = None  # (x, y, w, h) of the Blender window on the screen
        self.regions = None
        self.sidebar_box = None
        self.shots: dict[str, Path] = {}
        self.timings: dict[str, float] = {}

    # -- processes ------------------------------------------------------------------------
    def start_xvfb(self) -> None:
        r, w = os.pipe()
        self.xvfb = subprocess.Popen(
            ["Xvfb", "-displayfd", str(w), "-screen", "0", f"{SCREEN[0]}x{SCREEN[1]}x24",
             "-nolisten", "tcp"], pass_fds=(w,), stdout=subprocess.DEVNULL,
            stderr=open(self.out / "xvfb.log", "w"))
        os.close(w)
        with os.fdopen(r) as fh:
            number = fh.readline().strip()
        if not number:
            raise UITestError("Xvfb did not start (see xvfb.log)")
        self.display = f":{number}"
        self.log(f"Xvfb on display {self.display}")

    def env(self) -> dict:
        home = self.out / "home"
        env = dict(os.environ)
        env.update({
            "DISPLAY": self.display,
            "BLENDER_USER_CONFIG": str(home / "config"),
            "BLENDER_USER_SCRIPTS": str(home / "scripts"),
            "BLENDER_USER_DATAFILES": str(home / "datafiles"),
            "PYTHONNOUSERSITE": "1",
            "PYTHONPATH": "",
        })
        # Blender's temporary files (quit.blend, autosaves) stay in the test's folder too.
        tmp = home / "tmp"
        tmp.mkdir(parents=True, exist_ok=True)
        env.update({"TMPDIR": str(tmp), "TEMP": str(tmp), "TMP": str(tmp)})
        # Compiled numba kernels survive between runs unless --cold (what a first use costs).
        cache = (self.out / "home" / "numba-cache") if self.cold else \
            (self.out.parent / "ui-numba-cache")
        env["NUMBA_CACHE_DIR"] = str(cache)
        return env

    def start_blender(self, blend: Path, zip_path: Path) -> None:
        self.blender_args = (blend, zip_path)
        cmd = ["blender", "--factory-startup", "-p", "0", "0", str(SCREEN[0]), str(SCREEN[1]),
               str(blend), "--python", str(HERE / "harness.py"), "--",
               "--out", str(self.out), "--zip", str(zip_path)]
        self.log("starting " + " ".join(cmd))
        self.blender = subprocess.Popen(cmd, env=self.env(), stdin=subprocess.DEVNULL,
                                        stdout=open(self.out / "blender.log", "w"),
                                        stderr=subprocess.STDOUT, start_new_session=True)

    def cpu_seconds(self) -> dict:
        """CPU seconds of Blender and of Xvfb so far (from /proc: both still run)."""
        found = {}
        for name, proc in (("blender", self.blender), ("xvfb", self.xvfb)):
            try:
                fields = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
                found[name] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
            except (AttributeError, OSError, IndexError, ValueError):
                pass
        return found

    def stop(self) -> None:
        if self.blender is not None and self.blender.poll() is None:
            try:
                self.command("quit", timeout=15)
                self.blender.wait(30)
            except (UITestError, subprocess.TimeoutExpired):
                os.killpg(self.blender.pid, signal.SIGTERM)
                try:
                    self.blender.wait(10)
                except subprocess.TimeoutExpired:
                    os.killpg(self.blender.pid, signal.SIGKILL)
        self.stop_xvfb()

    def stop_xvfb(self) -> None:
        if self.xvfb is not None and self.xvfb.poll() is None:
            self.xvfb.terminate()
            self.xvfb.wait(10)

    # -- the harness ----------------------------------------------------------------------
    def state(self) -> dict:
        try:
            return json.loads((self.out / "state.json").read_text())
        except (OSError, ValueError):
            return {}

    def wait_for(self, what: str, pred, timeout: float, interval: float = 0.3) -> dict:
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            if self.blender.poll() is not None:
                raise UITestError(f"Blender exited ({self.blender.returncode}) while waiting "
                                  f"for {what}; see blender.log")
            st = self.state()
            if st and pred(st):
                return st
            time.sleep(interval)
        last = {k: v for k, v in self.state().items() if k != "install"}
        raise UITestError(f"timed out after {timeout:.0f} s waiting for {what}; last state: "
                          f"{json.dumps(last)[:600]}")

    def command(self, cmd: str, timeout: float = 120, **args):
        self.seq += 1
        name = f"{self.seq:04d}.json"
        tmp = self.out / "cmd" / (name + ".part")
        tmp.write_text(json.dumps({"cmd": cmd, "args": args}))
        os.replace(tmp, self.out / "cmd" / name)
        resp = self.out / "resp" / name
        t0 = time.monotonic()
        while not resp.exists():
            if self.blender.poll() is not None:
                raise UITestError(f"Blender exited during '{cmd}'; see blender.log")
            if time.monotonic() - t0 > timeout:
                raise UITestError(f"no answer to '{cmd}' within {timeout} s")
            time.sleep(0.1)
        answer = json.loads(resp.read_text())
        if not answer["ok"]:
            raise UITestError(f"'{cmd}' failed inside Blender:\n{answer['error']}")
        return answer["result"]

    # -- X ---------------------------------------------------------------------------------
    def xdo(self, *args: str) -> str:
        res = subprocess.run(["xdotool", *args], env={**os.environ, "DISPLAY": self.display},
                             capture_output=True, text=True, timeout=30)
        return res.stdout

    def find_window(self, timeout: float = 180) -> None:
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            ids = self.xdo("search", "--onlyvisible", "--name", "Blender").split()
            best = None
            for wid in ids:
                geo = dict(line.split("=") for line in
                           self.xdo("getwindowgeometry", "--shell", wid).split())
                rect = (int(geo["X"]), int(geo["Y"]), int(geo["WIDTH"]), int(geo["HEIGHT"]))
                if best is None or rect[2] * rect[3] > best[1][2] * best[1][3]:
                    best = (wid, rect)
            if best is not None and best[1][2] > 400:
                self.wid, self.win = best
                return
            if self.blender is not None and self.blender.poll() is not None:
                tail = (self.out / "blender.log").read_text(errors="replace").strip()
                if "failed to initialize display" in tail and not self.restarted:
                    # seen once, right after the packages were installed (the next run was
                    # fine): worth one more try with a new server, not a red test
                    self.log("Blender could not open the display; Xvfb and Blender once more")
                    self.restarted = True
                    self.stop_xvfb()
                    self.start_xvfb()
                    self.start_blender(*self.blender_args)
                    continue
                # it will not come: say why now rather than after the timeout
                raise UITestError(f"Blender exited ({self.blender.returncode}) before its window "
                                  f"appeared; the end of blender.log:\n{tail[-800:]}")
            time.sleep(1)
        raise UITestError("no Blender window appeared")

    def to_screen(self, x: float, y: float) -> tuple[int, int]:
        """Blender window coordinates (origin bottom left) to screen pixels."""
        wx, wy, _, wh = self.win
        return int(round(wx + x)), int(round(wy + wh - 1 - y))

    def region_box(self, area_type: str, region_type: str) -> tuple[int, int, int, int]:
        """Screen box (left, top, right, bottom) of a region of the largest such area."""
        areas = [a for a in self.regions["areas"] if a["type"] == area_type]
        area = max(areas, key=lambda a: a["width"] * a["height"])
        r = area["regions"][region_type]
        left, top = self.to_screen(r["x"], r["y"] + r["height"] - 1)
        return left, top, left + r["width"], top + r["height"]

    def status_bar_box(self) -> tuple[int, int, int, int]:
        """The status bar: the strip of the window below every area (not in screen.areas)."""
        bottom_of_areas = min(a["y"] for a in self.regions["areas"])
        left, top = self.to_screen(0, bottom_of_areas - 1)
        return left, top, left + self.regions["window"]["width"], top + bottom_of_areas

    def move(self, x: int, y: int) -> None:
        self.xdo("mousemove", str(x), str(y))
        time.sleep(0.3)

    def click(self, x: int, y: int) -> None:
        self.move(x, y)
        self.xdo("mousemove", str(x + 1), str(y))  # a motion event over the button first
        time.sleep(0.3)
        self.xdo("click", "1")

    def key(self, name: str) -> None:
        self.xdo("key", "--clearmodifiers", name)

    def screenshot(self, name: str) -> np.ndarray:
        path = self.out / f"{name}.png"
        # zlib level 1, no filter ("-quality 10"): 0.1 s of CPU a shot here instead of 0.5 s at
        # the default, for files a quarter larger (the docs' pictures are encoded anew)
        subprocess.run(["import", "-display", self.display, "-window", "root", "-quality", "10",
                        str(path)], check=True, timeout=60)
        self.screenshots_taken += 1
        self.shots[name] = path
        return read_png(path)

    def settle(self, quiet: float = 1.0, timeout: float = 15) -> None:
        """Wait until the sidebar has not been redrawn for ``quiet`` seconds.

        Blender slides panels into a new layout over several redraws (after a run the "Last
        run" box appears and pushes the sub-panels down); a screenshot in between shows them
        overlapping.
        """
        t0 = time.monotonic()
        last, since = self.state().get("sidebar_draws"), time.monotonic()
        while time.monotonic() - t0 < timeout:
            time.sleep(0.2)
            now = self.state().get("sidebar_draws")
            if now != last:
                last, since = now, time.monotonic()
            elif time.monotonic() - since >= quiet:
                return

    def refresh_regions(self) -> None:
        self.regions = self.command("regions")


def read_png(path: Path) -> np.ndarray:
    raw = subprocess.run([CONVERT, str(path), "-depth", "8", "rgb:-"], check=True,
                         capture_output=True, timeout=60).stdout
    return np.frombuffer(raw, np.uint8).reshape(SCREEN[1], SCREEN[0], 3)


def crop(img: np.ndarray, box) -> np.ndarray:
    left, top, right, bottom = box
    return img[top:bottom, left:right]


def changed_fraction(a: np.ndarray, b: np.ndarray, threshold: int = 24) -> float:
    d = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=2)
    return float((d > threshold).mean())


def marked_buttons(img: np.ndarray, box) -> list[list[tuple[int, int, int, int]]]:
    """Rectangles painted in the marker colour inside ``box``, as rows of buttons (top first).

    Returns a list of rows; each row is a list of (left, top, right, bottom) screen boxes.
    """
    left, top, _, _ = box
    sub = crop(img, box).astype(np.int16)
    mask = (sub[..., 0] > 200) & (sub[..., 1] < 70) & (sub[..., 2] > 200)
    rows = np.flatnonzero(mask.sum(axis=1) >= 6)
    bands, out = [], []
    for r in rows:
        if bands and r - bands[-1][1] <= 1:
            bands[-1][1] = r
        else:
            bands.append([r, r])
    for r0, r1 in bands:
        if r1 - r0 < 6:  # not a button (a stray line of the colour)
            continue
        # Buttons of an aligned row touch, with a thin outline between them: split at any
        # column that is not mostly marker (text and icons cover only part of a column).
        cols = np.flatnonzero(mask[r0:r1 + 1].mean(axis=0) > 0.3)
        segs = []
        for c in cols:
            if segs and c - segs[-1][1] <= 1:
                segs[-1][1] = c
            else:
                segs.append([c, c])
        row = [(left + c0, top + r0, left + c1 + 1, top + r1 + 1) for c0, c1 in segs
               if c1 - c0 >= 20]
        if row:
            out.append(row)
    return out


def marked_tabs(img: np.ndarray, box) -> list[tuple[int, int, int, int]]:
    """Category tabs painted in the marker colour along the right edge of ``box``, top first."""
    left, top, right, _ = box
    strip = (max(left, right - 30), box[1], right, box[3])
    sub = crop(img, strip).astype(np.int16)
    mask = (sub[..., 0] > 200) & (sub[..., 1] < 70) & (sub[..., 2] > 200)
    rows = np.flatnonzero(mask.sum(axis=1) >= 4)
    runs = []
    for r in rows:
        if runs and r - runs[-1][1] <= 2:
            runs[-1][1] = r
        else:
            runs.append([r, r])
    tabs = []
    for r0, r1 in runs:
        if r1 - r0 < 15:
            continue
        cols = np.flatnonzero(mask[r0:r1 + 1].any(axis=0))
        tabs.append((strip[0] + cols[0], top + r0, strip[0] + cols[-1] + 1, top + r1 + 1))
    return tabs


def distinct_pairs(shots) -> list[tuple[int, int]]:
    """Index pairs (i, j) of screenshots taken while running that certainly show different
    iterates: each shot i is paired with the first later shot j whose bracket starts after
    the end of i's (a shot may catch the same iterate twice when a step takes longer than a
    screenshot). Pairs do not overlap: the next pair starts at j."""
    pairs, i = [], 0
    while i < len(shots):
        j = next((j for j in range(i + 1, len(shots)) if shots[j][1][0] > shots[i][1][1]), None)
        if j is None:
            break
        pairs.append((i, j))
        i = j
    return pairs


#: What Ctrl+C over each button the scenario presses copies (its operator and arguments).
BUTTONS = {
    "bpy.ops.moebius.relax(append=False)": "relax",
    "bpy.ops.moebius.relax(append=True)": "continue",
    "bpy.ops.moebius.convert()": "convert",
    "bpy.ops.moebius.apply_frame()": "apply",
    "bpy.ops.moebius.clear_animation()": "clear",
    "bpy.ops.moebius.live()": "live",
}
#: Live: the pinned points of the relaxed curve, and the drag of the first (a share of the way
#: to the other pin on the screen, and a sideways share of it): across the circle.
LIVE_PINS = (0, 80)
LIVE_DRAG = (0.55, 0.2)


def centre(box) -> tuple[int, int]:
    return (box[0] + box[2]) // 2, (box[1] + box[3]) // 2


# ---------------------------------------------------------------------------------------------
# The scenario

class Scenario:
    def __init__(self, s: Session, report: dict) -> None:
        self.s = s
        self.report = report
        self.checks: dict[str, bool] = report.setdefault("checks", {})

    def check(self, name: str, ok: bool, detail=None) -> None:
        self.checks[name] = bool(ok)
        # Blender's CPU seconds so far: what each step of the scenario costs
        self.report.setdefault("blender_cpu_at", {})[name] = self.s.cpu_seconds().get("blender")
        self.s.log(f"{'ok  ' if ok else 'FAIL'} {name}" + (f": {detail}" if detail else ""))

    def marked_screenshot(self, path: str, tag: str) -> np.ndarray:
        """A screenshot with one theme colour set to the marker colour (restored right after)."""
        s = self.s
        s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))  # no hover highlight on a button
        for on in (True, False):
            draws = s.command("marker", path=path, on=on)["sidebar_draws"]
            s.wait_for("the sidebar to be redrawn",
                       lambda st, d=draws: st.get("sidebar_draws", 0) > d, timeout=30)
            time.sleep(0.5)
            if on:
                img = s.screenshot(f"marker-{tag}")
        return img

    def show_moebius_tab(self) -> None:
        """Click the Möbius tab of the sidebar (the last category tab: add-ons come last)."""
        s = self.s
        img = self.marked_screenshot("view_3d.space.tab_inactive", "tabs")
        tabs = marked_tabs(img, s.region_box("VIEW_3D", "UI"))
        self.report["tabs"] = [list(t) for t in tabs]
        if not tabs:
            raise UITestError("no category tabs found in the sidebar")
        draws = s.state().get("panel_draws", 0)
        s.click(*centre(tabs[-1]))
        try:
            s.wait_for("the Möbius panel", lambda st: st.get("panel_draws", 0) > draws, 20)
        except UITestError:
            pass  # reported by the caller's check

    def press(self, box, what: str, effect, timeout: float = 600) -> float:
        """Click ``box`` and wait for ``effect(state)``; return the seconds it took.

        A click that Blender did not take (seen as: the harness timer kept ticking, so Blender
        was idle, for 8 s without the effect) is repeated, at most twice; while Blender is busy
        (numba compiling inside the operator: the timer stalls) the wait goes on.
        """
        s = self.s
        t0 = time.monotonic()
        for attempt in range(3):
            s.click(*centre(box))
            s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))
            idle_since = time.monotonic()
            while time.monotonic() - t0 < timeout:
                st = s.state()
                if effect(st):
                    self.report.setdefault("clicks", {})[what] = attempt + 1
                    return time.monotonic() - t0
                if time.time() - st.get("t", 0) > 1.5:  # timer stalled: Blender is busy
                    idle_since = time.monotonic()
                elif time.monotonic() - idle_since > 8:
                    s.log(f"click on {what} not taken (attempt {attempt + 1}); again")
                    break
                time.sleep(0.1)
            else:
                break
        raise UITestError(f"clicking {what} had no effect")

    def identify(self, box) -> str:
        """The Python command of the operator button at ``box``, as Blender copies it: Ctrl+C
        with the mouse over an operator button copies ``bpy.ops.moebius.relax(append=False)``
        (Blender's ui_but_copy_operator), which the harness reads from the clipboard."""
        s = self.s
        s.command("clipboard", set="")
        x, y = centre(box)
        s.move(x, y)
        s.move(x + 1, y)  # a motion event over the button makes it the active one
        s.key("ctrl+c")
        for _ in range(10):
            time.sleep(0.2)
            text = s.command("clipboard")["clipboard"]
            if text:
                return text
        return ""

    def scroll_sidebar(self, clicks: int) -> None:
        """Turn the mouse wheel over the sidebar: ``clicks`` > 0 scrolls down, < 0 up."""
        s = self.s
        x, y = centre(s.region_box("VIEW_3D", "UI"))
        s.move(x, y)
        s.xdo("click", "--repeat", str(abs(clicks)), "--delay", "30", "5" if clicks > 0 else "4")
        s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))
        s.settle()

    def buttons(self, tag: str, wanted: tuple[str, ...]) -> dict:
        """Find the ``wanted`` buttons (keys of :data:`BUTTONS`) in the sidebar as a person
        would: the operator buttons are the rectangles painted in the marker colour for one
        frame (theme ``wcol_tool.inner``), and each is told by what Ctrl+C over it copies,
        top to bottom until every wanted one is known; the sidebar is scrolled down a page at
        a time when one is not in view (the panel is longer than the window after a run).
        Returns ``{name: box}`` in screen pixels, valid until the sidebar scrolls again."""
        s = self.s
        panel = s.region_box("VIEW_3D", "UI")
        self.scroll_sidebar(-40)  # from the top
        found: dict = {}
        seen: list = []
        identified: list = []  # every page's, for the report
        for page in range(6):
            img = self.marked_screenshot("user_interface.wcol_tool.inner", f"{tag}-{page}")
            boxes = [box for row in marked_buttons(img, panel) for box in row]
            for box in boxes:
                if all(w in found for w in wanted):
                    break
                if any(box == b for b, _ in seen):
                    continue
                command = self.identify(box)
                seen.append((box, command))
                identified.append([page, list(box), command])
                name = BUTTONS.get(command)
                if name is not None and name not in found:
                    found[name] = box
            s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))  # no tooltip left over
            if all(w in found for w in wanted):
                break
            self.scroll_sidebar(8)
            seen.clear()  # the same boxes hold other buttons now,
            found.clear()  # and those found are elsewhere: the wanted ones on one page
        self.report.setdefault("buttons", {})[tag] = {
            "found": {k: list(v) for k, v in found.items()}, "identified": identified}
        missing = [w for w in wanted if w not in found]
        if missing:
            raise UITestError(f"buttons not found in the sidebar: {missing} (identified: "
                              f"{[c for *_, c in identified]})")
        return found

    def run(self) -> None:
        s, t = self.s, self.s.timings
        t0 = time.monotonic()
        s.find_window()
        st = s.wait_for("the add-on to be installed and enabled",
                        lambda st: st.get("ready") or st.get("errors"), timeout=300)
        if not st.get("ready"):
            raise UITestError("add-on install failed:\n" + "\n".join(st["errors"]))
        self.report["install"] = st["install"]
        t["blender_ready"] = time.monotonic() - t0
        time.sleep(2)
        s.refresh_regions()
        s.screenshot("01-opened")

        self.show_moebius_tab()
        self.check("moebius_tab_shown", s.state().get("panel_draws", 0) > 0)
        s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))
        s.settle()
        s.screenshot("02-panel")

        # Convert.
        b = self.buttons("before-convert", ("convert",))
        t["convert_s"] = self.press(b["convert"], "Convert",
                                    lambda st: st.get("active") == "Helix.moebius")
        self.check("convert_made_polygon", "Helix.moebius" in s.state()["objects"])
        self.report["converted"] = s.command("record_start")
        s.settle()
        idle = s.screenshot("03-converted")

        # Relax, screenshots while it runs, then Esc.
        b = self.buttons("before-relax", ("relax",))
        t1 = time.monotonic()
        t["relax_start_s"] = self.press(b["relax"], "Relax", lambda st: st.get("running"))
        # The first iterate may wait for numba to compile (or load) the flow's kernels.
        s.wait_for("the first iterate drawn", lambda st: st.get("view_iteration") is not None
                   or not st.get("running"), timeout=300, interval=0.1)
        t["relax_first_iterate_s"] = time.monotonic() - t1
        view = s.region_box("VIEW_3D", "WINDOW")
        panel = s.region_box("VIEW_3D", "UI")
        status = s.status_bar_box()
        # Each shot is bracketed by the iterate the 3D view showed when last drawn, read just
        # before and just after it: the shot shows an iterate in [before, after].
        running_shots = []
        while len(running_shots) < 16 and len(distinct_pairs(running_shots)) < 3:
            time.sleep(0.5)
            before = s.state().get("view_iteration")
            img = s.screenshot(f"04-running-{len(running_shots) + 1}")
            st = s.state()
            if not st.get("running"):
                break
            if before is None or st.get("view_iteration") is None:
                continue
            running_shots.append((img, (before, st.get("view_iteration")),
                                  st.get("live_energy")))
        s.key("Escape")
        t_esc = time.monotonic()
        st = s.wait_for("the run to stop after Esc", lambda st: not st.get("running"),
                        timeout=60, interval=0.1)
        t["esc_to_stop_s"] = time.monotonic() - t_esc
        iters = [it for _, it, _ in running_shots]
        diffs = [changed_fraction(crop(running_shots[i][0], view),
                                  crop(running_shots[j][0], view))
                 for i, j in distinct_pairs(running_shots)]
        self.report["running"] = {
            "shots": len(running_shots), "iterations_at_shots": iters,
            "energies_at_shots": [e for *_, e in running_shots],
            "viewport_changed_fraction": diffs,
        }
        self.check("screenshots_while_running", len(running_shots) >= 3,
                   f"{len(running_shots)} shots at iterations {iters}")
        self.check("curve_changes_while_running",
                   len(diffs) >= 3 and all(d > 0.002 for d in diffs),
                   "changed pixel fractions " + ", ".join(f"{d:.3%}" for d in diffs))
        self.check("iterations_advance_while_running",
                   len(iters) >= 2 and iters[-1][0] > iters[0][1]
                   and all(b_[0] >= a[0] for a, b_ in pairwise(iters)), iters)
        if running_shots:
            last = running_shots[-1][0]
            sd = changed_fraction(crop(last, status), crop(idle, status))
            pd = changed_fraction(crop(last, panel), crop(idle, panel))
            self.report["running"].update(status_bar_changed=sd, panel_changed=pd)
            self.check("status_text_shows", sd > 0.01, f"status bar pixels changed {sd:.1%}")
            self.check("panel_shows_progress", pd > 0.005, f"panel pixels changed {pd:.1%}")
        s.settle()
        s.screenshot("05-stopped")
        res = s.command("check_run", cancelled=True)
        self.report["after_esc"] = res
        for k, v in res["ok"].items():
            self.check(f"esc_{k}", v)

        # Clear Flow Animation brings back the start; Relax again runs to the end.
        b = self.buttons("before-clear", ("clear",))
        self.press(b["clear"], "Clear Flow Animation", lambda st: st.get("energy_keys") == 0)
        s.settle()
        res = s.command("check_cleared")
        self.report["after_clear"] = res
        for k, v in res["ok"].items():
            self.check(f"clear_{k}", v)
        s.screenshot("06-cleared")
        b = self.buttons("before-full-run", ("relax",))
        t1 = time.monotonic()
        self.press(b["relax"], "Relax (full run)", lambda st: st.get("running"))
        # Half way through the untangling (about 70 iterates in all) for the docs' picture.
        s.wait_for("iterate 30", lambda st: (st.get("view_iteration") or 0) >= 30
                   or not st.get("running"), timeout=600, interval=0.2)
        s.screenshot("07-running-full")
        s.wait_for("the second run to finish", lambda st: not st.get("running"), timeout=900,
                   interval=0.5)
        t["full_run_s"] = time.monotonic() - t1
        s.settle()
        self.scroll_sidebar(-40)  # the panel from its top, for the picture
        s.settle(quiet=2.0)
        s.screenshot("08-finished")
        res = s.command("check_run", cancelled=False)
        self.report["full_run"] = res
        for k, v in res["ok"].items():
            self.check(f"full_{k}", v)
        self.check("full_run_untangled", res["energy_end"] < 4.5,
                   f"energy {res['energy_start']:.4g} -> {res['energy_end']:.6g} "
                   f"in {res['iterations']} iterations")

        self.live()

        # The energy curve in a Graph Editor.
        s.sidebar_box = s.region_box("VIEW_3D", "UI")  # before the split halves it
        self.report["graph"] = s.command("graph_editor")
        s.refresh_regions()
        time.sleep(1.0)
        s.settle()
        s.screenshot("09-graph")
        t["scenario_s"] = time.monotonic() - t0

    def _live_run(self, tag: str, box=None) -> tuple[dict, tuple]:
        """Press Live (at ``box`` if Ctrl+C over it still copies the Live operator, else
        found anew), go to Edit Mode (Tab), click the first pin (it alone selected), drag it
        with G across the view taking screenshots, confirm with a click. Returns what the
        drag did and where the Live button was."""
        s = self.s
        if box is None or BUTTONS.get(self.identify(box)) != "live":
            box = self.buttons(f"before-{tag}", ("live",))["live"]
        t1 = time.monotonic()
        self.press(box, f"Live ({tag})", lambda st: st.get("live"))
        s.wait_for("the live run's first iterations",
                   lambda st: st.get("live_iteration", 0) > 0 or not st.get("live"),
                   timeout=600, interval=0.2)
        self.s.timings[f"{tag}_first_iteration_s"] = time.monotonic() - t1
        view = s.region_box("VIEW_3D", "WINDOW")
        s.move(*centre(view))
        s.key("Tab")
        s.wait_for("Edit Mode", lambda st: st.get("mode") == "EDIT", timeout=30)
        time.sleep(0.5)
        p = s.command("pin_screen", index=LIVE_PINS[0])
        x, y = s.to_screen(p["x"], p["y"])
        s.click(x, y)  # select this pin alone, as a person does before G
        time.sleep(0.5)
        shots = [s.screenshot(f"{tag}-1-before-drag")]
        header = s.region_box("VIEW_3D", "HEADER")
        q = s.command("pin_screen", index=LIVE_PINS[1])
        cx, cy = s.to_screen(q["x"], q["y"])
        dx = LIVE_DRAG[0] * (cx - x) - LIVE_DRAG[1] * (cy - y)
        dy = LIVE_DRAG[0] * (cy - y) + LIVE_DRAG[1] * (cx - x)
        s.move(x, y)
        s.key("g")
        # G has taken once the header shows the move's numbers (a loaded machine is slow)
        for _ in range(20):
            s.xdo("mousemove", str(x + 1), str(y))
            s.xdo("mousemove", str(x), str(y))
            if changed_fraction(crop(s.screenshot(f"{tag}-1-grab"), header),
                                crop(shots[0], header)) > 0.01:
                break
        steps = 6
        for k in range(1, steps + 1):
            s.xdo("mousemove", str(int(round(x + dx * k / steps))),
                  str(int(round(y + dy * k / steps))))
            for _ in range(10):  # the effect, not a fixed time: wait until the view shows it
                time.sleep(0.5)
                img = s.screenshot(f"{tag}-2-drag-{k}")
                if changed_fraction(crop(img, view), crop(shots[-1], view)) > 0.001:
                    break
            shots.append(img)
        end = (int(round(x + dx)), int(round(y + dy)))
        s.xdo("click", "1")  # confirm the move where the mouse is
        time.sleep(1.5)
        s.screenshot(f"{tag}-3-after-drag")
        crops = [crop(img, view) for img in shots]  # the shots during the drag
        diffs = [changed_fraction(a, b_) for a, b_ in pairwise(crops)]
        p = s.command("pin_screen", index=LIVE_PINS[0])
        px, py = s.to_screen(p["x"], p["y"])
        return {"start": [x, y], "end": list(end), "pin_on_screen": [px, py],
                "pin_off_by_px": float(np.hypot(px - end[0], py - end[1])),
                "changed_fraction": diffs}, box

    def live(self) -> None:
        """Live on the relaxed curve with two pinned points: drag one with the mouse, keep
        the result (Enter) and check the recording; one Ctrl+Z undoes it all; again, and Esc
        puts everything back."""
        s = self.s
        s.refresh_regions()
        self.report["live_prepare"] = s.command("live_prepare", pins=list(LIVE_PINS))
        # 1. drag, Tab back to Object Mode, Enter keeps it (Record is on)
        t0 = time.monotonic()
        drag, box = self._live_run("live")
        self.report["live_drag"] = drag
        self.check("live_screenshots_differ_during_drag",
                   all(d > 0.001 for d in drag["changed_fraction"]),
                   "changed pixel fractions " + ", ".join(f"{d:.3%}" for d in
                                                          drag["changed_fraction"]))
        self.check("live_pin_ends_under_the_mouse", drag["pin_off_by_px"] <= 3.0,
                   f"{drag['pin_off_by_px']:.1f} px from where the mouse left it")
        s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))
        s.key("Tab")
        s.wait_for("Object Mode", lambda st: st.get("mode") == "OBJECT", timeout=30)
        s.key("Return")
        first = self.report["live_prepare"]["frame"]
        # ended, and the recording keyed (the scene goes to its last frame)
        s.wait_for("Live to end (Enter)", lambda st: not st.get("live")
                   and st.get("frame") != first, timeout=120)
        s.settle()
        s.screenshot("live-4-kept")
        res = s.command("check_live", record=True)
        self.report["live_record"] = res
        self.check("live_recorded_frames_never_cross", res.get("never_cross", False),
                   f"{res.get('recorded_frames')} frames, least distance "
                   f"{res.get('least_distance')}, {res.get('certify_error', '')}")
        self.check("live_recording_moved", res.get("moved", 0.0) > 0.0)
        # 2. one Ctrl+Z: the scene before Live
        s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))
        s.key("ctrl+z")
        time.sleep(2.0)
        res = s.command("check_live", compare=True)
        self.report["live_undo"] = res
        self.check("live_one_undo_restores", res["points_equal"] and res["keys_equal"],
                   f"points off by {res['points_maxdiff']:.3g}, keys equal {res['keys_equal']}")
        # 3. again, and Esc: everything as before Live, to the bit
        s.command("live_prepare", pins=list(LIVE_PINS))
        drag, _ = self._live_run("live-esc", box)
        self.report["live_esc_drag"] = drag
        s.move(*centre(s.region_box("VIEW_3D", "WINDOW")))
        s.key("Escape")
        s.wait_for("Live to end (Esc)", lambda st: not st.get("live"), timeout=60)
        time.sleep(1.0)
        s.screenshot("live-5-esc")
        res = s.command("check_live", compare=True)
        self.report["live_esc"] = res
        self.check("live_esc_restores_the_start", res["points_equal"] and res["keys_equal"],
                   f"points off by {res['points_maxdiff']:.3g}, keys equal {res['keys_equal']}")
        s.key("Tab")
        s.wait_for("Object Mode", lambda st: st.get("mode") == "OBJECT", timeout=30)
        s.timings["live_s"] = time.monotonic() - t0


def docs_images(s: Session, dest: Path) -> list[str]:
    """Small PNGs for the docs: the panel, a run in progress, the Graph Editor."""
    dest.mkdir(parents=True, exist_ok=True)
    made = []
    jobs = [
        ("08-finished", "ui-panel.png", ["-crop", "{ui}", "+repage"]),
        ("07-running-full", "ui-running.png", ["-resize", "800x"]),
        ("09-graph", "ui-graph.png", ["-resize", "800x"]),
        ("live-1-before-drag", "live-1-pinned.png", ["-resize", "800x"]),
        ("live-2-drag-3", "live-2-dragging.png", ["-resize", "800x"]),
        ("live-2-drag-6", "live-3-dragged.png", ["-resize", "800x"]),
    ]
    l_, t_, r_, b_ = s.sidebar_box or (0, 0, 0, 0)
    for src, name, ops in jobs:
        path = s.shots.get(src)
        if path is None:
            continue
        ops = [o.format(ui=f"{r_ - l_}x{b_ - t_}+{l_}+{t_}") for o in ops]
        subprocess.run([CONVERT, str(path), *ops, "-strip", "-colors", "128",
                        f"PNG8:{dest / name}"], check=True, timeout=60)
        made.append(str(dest / name))
    return made


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "ui")
    ap.add_argument("--docs-img", type=Path, help="also write small PNGs for the docs here")
    ap.add_argument("--cold", action="store_true",
                    help="empty numba cache: include the first-use compile in the timings")
    args = ap.parse_args(argv)
    missing = missing_tools()
    if missing:
        print("ui-test needs Debian packages: " + " ".join(missing) +
              " (make ui-test installs them with apt-get)", file=sys.stderr)
        return 2
    out = args.out.resolve()
    if out.exists() and any(out.iterdir()):
        if not (out / "driver.log").exists():  # never wipe a folder this script did not make
            print(f"{out} exists and is not an earlier ui-test output; choose another --out",
                  file=sys.stderr)
            return 2
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.monotonic()
    logfile = open(out / "driver.log", "w")

    def log(msg: str) -> None:
        line = f"[{time.monotonic() - t_start:7.1f} s] {msg}"
        print(line, flush=True)
        logfile.write(line + "\n")
        logfile.flush()

    report: dict = {"screenshots": [], "timings": {}}
    s = Session(out, args.cold, log)
    status = 1
    try:
        zip_path = legacy_zip(out / "moebius_addon-legacy.zip")
        blend = out / "knot.blend"
        t0 = time.monotonic()
        subprocess.run(["blender", "-b", "--factory-startup", "--python",
                        str(HERE / "make_scene.py"), "--", str(blend)], check=True,
                       stdout=open(out / "make_scene.log", "w"), stderr=subprocess.STDOUT,
                       env={**os.environ, "PYTHONNOUSERSITE": "1"}, timeout=600)
        s.timings["make_scene_s"] = time.monotonic() - t0
        s.start_xvfb()
        s.start_blender(blend, zip_path)
        Scenario(s, report).run()
        if args.docs_img:
            report["docs_images"] = docs_images(s, args.docs_img)
        status = 0 if all(report["checks"].values()) else 1
    except (UITestError, subprocess.SubprocessError, OSError) as err:
        report["error"] = str(err)
        log(f"ERROR {err}")
        try:
            s.screenshot("99-error")
        except Exception:  # noqa: BLE001 - best effort
            pass
    finally:
        cpu = s.cpu_seconds()
        s.stop()
        report["timings"] = {**s.timings, "total_s": time.monotonic() - t_start}
        # the driver and what it waited for, Blender, Xvfb
        report["cpu_s"] = {**cpu, "all": sum(os.times()[:4])}
        report["screenshots_taken"] = s.screenshots_taken
        report["screenshots"] = sorted(str(p.relative_to(out)) for p in s.shots.values())
        report["passed"] = status == 0
        (out / "report.json").write_text(json.dumps(report, indent=1, default=float))
        failed = [k for k, v in report.get("checks", {}).items() if not v]
        log(f"{'PASSED' if status == 0 else 'FAILED'}: {len(report.get('checks', {}))} checks"
            + (f", failing: {failed}" if failed else "") + f"; report {out / 'report.json'}")
    return status


if __name__ == "__main__":
    sys.exit(main())
