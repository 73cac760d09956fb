"""Rates of a live relaxation (core.runs.live): how often the viewport gets a new state, how long a
pin move takes to show, and whether the main thread stays responsive while the run works in a
background thread. Prints measurements; it is not a test.

The main thread plays Blender's part: a timer every 1/60 s (bpy.app.timers in the add-on) that
posts the pins' targets, takes the newest state and writes its coordinates (with ``--bpy``
into a real curve object through the bpy module, else into a numpy buffer). Every 0.5 s a pin
is moved by a fifth of an edge; the time from that post to the first tick that shows the pin
there is the move's latency. The timer's lateness (how much later than asked a tick ran) is
the main thread's responsiveness: numba's kernels hold the GIL while they run (none is
compiled nogil), and the run's thread sleeps ``--pause`` seconds after every state to let the
main thread in::

    NUMBA_NUM_THREADS=2 PYTHONPATH=. .venv/bin/python bench/live_rates.py
    NUMBA_NUM_THREADS=2 PYTHONPATH=. .venv/bin/python bench/live_rates.py --scene knot --bpy
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from cables_tree import plates_scene  # noqa: E402

from moebius_addon import core  # noqa: E402
from moebius_addon.core.runs.live import LiveDriver, LiveRelaxation  # noqa: E402

TICK = 1.0 / 60.0


def knot_scene(n: int = 1000):
    P = np.asarray(core.knots.named("3_1", n))
    return dict(P=P, pinned=[0, n // 2]), f"3_1, {n} edges, 2 pins"


def cables_scene(cables: int = 10, edges: int = 100):
    parts = plates_scene(cables, edges, spacing=0.1)
    return (dict(P=parts, pinned=[[0, len(p) - 1] for p in parts], closed=False),
            f"{cables} cables x {edges} edges, both ends pinned")


class Writer:
    """Where the ticks write the coordinates: a bpy curve (``--bpy``) or a numpy buffer."""

    def __init__(self, parts, closed: bool, use_bpy: bool):
        self.bpy = None
        if use_bpy:
            import bpy

            curve = bpy.data.curves.new("Live", "CURVE")
            for P in parts:
                sp = curve.splines.new("POLY")
                sp.points.add(len(P) - 1)
                sp.use_cyclic_u = closed
            self.curve = curve
            self.bpy = bpy
        self.buf = [np.empty((len(P), 4)) for P in parts]

    def write(self, parts) -> None:
        for k, P in enumerate(parts):
            self.buf[k][:, :3] = P
            self.buf[k][:, 3] = 1.0
            if self.bpy is not None:
                self.curve.splines[k].points.foreach_set("co", self.buf[k].ravel())
        if self.bpy is not None:
            self.curve.update_tag()


def baseline(kwargs: dict, seconds: float, engine: str) -> float:
    """Iterations per second of the same run stepped in the calling thread, no thread, no
    viewport: what the machine gives right now."""
    run = LiveRelaxation(engine=engine, **kwargs)
    for _ in range(3):
        run.step()
    t0, n = time.perf_counter(), run.nit
    while time.perf_counter() - t0 < seconds and run.step():
        pass
    return (run.nit - n) / (time.perf_counter() - t0)


def measure(kwargs: dict, seconds: float, pause: float, use_bpy: bool, engine: str,
            threads: int | None = None) -> dict:
    t = time.perf_counter()
    run = LiveRelaxation(engine=engine, **kwargs)
    setup = time.perf_counter() - t
    # the first steps compile or load kernels: not part of the rates
    for _ in range(3):
        run.step()
    parts = run.x if isinstance(run.x, list) else [run.x]
    writer = Writer(parts, kwargs.get("closed", True), use_bpy)
    pins = run.pin_positions.copy()
    edge = float(np.mean(np.linalg.norm(np.diff(parts[0], axis=0), axis=1)))
    drv = LiveDriver(run, pause=pause, threads=threads)
    late, shown, latencies = [], 0, []
    pending = None  # (target, posted at)
    t0 = time.perf_counter()
    next_tick, next_move, k = t0, t0 + 0.5, 0
    writes = []
    while time.perf_counter() - t0 < seconds:
        now = time.perf_counter()
        if now < next_tick:
            time.sleep(next_tick - now)
        now = time.perf_counter()
        late.append(now - next_tick)
        next_tick += TICK
        if next_tick < now:  # a tick missed altogether: the next one is due now
            next_tick = now
        if pending is None and now >= next_move:
            k += 1
            pins = pins.copy()
            pins[0] += 0.2 * edge * np.array([np.cos(k), np.sin(k), 0.3])
            drv.post(pins=pins)
            pending = (pins[0].copy(), time.perf_counter())
            next_move = now + 0.5
        frame = drv.latest()
        if frame is None:
            continue
        w = time.perf_counter()
        writer.write(frame.parts)
        writes.append(time.perf_counter() - w)
        shown += 1
        if pending is not None and np.array_equal(
                np.concatenate(frame.parts)[run.handles[0]], pending[0]):
            latencies.append(time.perf_counter() - pending[1])
            pending = None
    elapsed = time.perf_counter() - t0
    drv.close()
    if drv.error is not None:
        raise drv.error
    late = np.array(late)
    return dict(setup=setup, engine=run.engine.name, updates=shown / elapsed, nit=run.nit,
                steps=run.nit / elapsed, late_p50=np.median(late), late_p95=np.percentile(late, 95),
                late_max=late.max(), lat=np.array(latencies), moves=k,
                write=np.median(writes) if writes else float("nan"))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", choices=("knot", "cables", "all"), default="all")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--pause", type=float, default=0.002,
                    help="seconds the run's thread sleeps after each state (LiveDriver)")
    ap.add_argument("--engine", default="auto")
    ap.add_argument("--bpy", action="store_true", help="write into a real bpy curve")
    ap.add_argument("--threads", type=int, default=None,
                    help="numba threads of the live run (default LiveDriver's: one fewer than "
                         "numba has)")
    ap.add_argument("--growth", type=float, nargs="+", default=[None],
                    help="step growths to compare, one run each (default the live run's own, "
                         "core.runs.live.LIVE_GROWTH)")
    args = ap.parse_args(argv)
    print(f"cores {os.cpu_count()}, numba threads {os.environ.get('NUMBA_NUM_THREADS', '-')}, "
          f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}, pause {args.pause} s, "
          f"writes into {'a bpy curve' if args.bpy else 'numpy'}, live run's numba threads "
          f"{args.threads or 'LiveDriver default'}")
    scenes = {"knot": knot_scene, "cables": cables_scene}
    for name, growth in [(n, g) for n in (scenes if args.scene == "all" else [args.scene])
                         for g in args.growth]:
        kwargs, words = scenes[name]()
        if growth is not None:
            kwargs["growth"] = growth
            words += f", growth {growth:g}"
        base = baseline(kwargs, min(args.seconds, 4.0), args.engine)
        r = measure(kwargs, args.seconds, args.pause, args.bpy, args.engine, args.threads)
        lat = r["lat"]
        print(f"{words} ({r['engine']} engine): {r['updates']:.1f} viewport updates/s, "
              f"{r['steps']:.1f} iterations/s; pin move to first frame showing it: median "
              f"{1e3 * np.median(lat):.0f} ms, max {1e3 * lat.max():.0f} ms over {len(lat)} of "
              f"{r['moves']} moves; main-thread timer late by median "
              f"{1e3 * r['late_p50']:.1f} ms, 95% {1e3 * r['late_p95']:.1f} ms, max "
              f"{1e3 * r['late_max']:.1f} ms; write {1e3 * r['write']:.2f} ms; set-up "
              f"{r['setup']:.1f} s; the same run without thread or viewport just before: "
              f"{base:.1f} iterations/s", flush=True)
    print(f"load after {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
