"""``scene.moebius``: the settings of the panel and the statistics of the last run."""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from . import labels


def _stat(key: str, default):
    """Read-only property getter backed by an ID property the operators write."""
    def get(self):
        return self.get("_stats", {}).get(key, default)
    return get


class MoebiusSettings(bpy.types.PropertyGroup):
    """Settings of the Möbius panel (``scene.moebius``)."""

    # Polygon
    edges: IntProperty(
        name="Edges", default=100, min=9, soft_max=1000, max=1_000_000,
        description="Edges of each converted component (at least 9, below which the start "
                    "check cannot judge a knot; on the exact engine the cost per iteration "
                    "grows as edges², see Advanced ▸ Engine)",
    )
    use_edge_length: BoolProperty(
        name="Use Edge Length", default=False,
        description="Choose the number of edges from a target edge length instead",
    )
    edge_length: FloatProperty(
        name="Edge Length", default=0.05, min=1e-6, soft_min=1e-3, subtype="DISTANCE",
        description="Target edge length in object units (edges = curve length / this)",
    )
    close_open: BoolProperty(
        name="Close Open Splines", default=False,
        description="Join the ends of open splines instead of refusing them",
    )
    keep_open: BoolProperty(
        name="Keep Open Splines", default=False,
        description="Keep open splines open, their ends where they are, and relax them as open "
                    "curves (exact engine; pin the ends with Pin Selected Points to hold them)",
    )
    # Flow
    energy: EnumProperty(
        name="Energy", default=labels.DEFAULT_ENERGY,
        items=[(key, label, desc) for key, label, desc in labels.ENERGIES],
        description="The energy the flow minimizes (and keys on the object)",
    )
    # the energies' parameters (α, β) and weights (Stiffness): one setting each, added below
    # from the core's records
    metric: EnumProperty(
        name="Metric", default=labels.DEFAULT_METRIC,
        items=[(key, label, desc) for key, label, desc in labels.METRICS],
        description="Inner product that turns the energy's derivative into a gradient",
    )
    max_iterations: IntProperty(
        name="Max Iterations", default=labels.DEFAULT_MAX_ITERATIONS, min=1, soft_max=5000,
        description="Stop after this many accepted steps",
    )
    tolerance: FloatProperty(
        name="Tolerance", default=labels.DEFAULT_TOLERANCE, min=0.0, precision=8,
        description="Stop once the gradient norm in the metric (projected onto the "
                    "constraints for the exact-constraint methods) is smaller than this",
    )
    settle: FloatProperty(
        name="Stop When Still", default=100 * labels.DEFAULT_SETTLE, min=0.0, soft_max=5.0,
        precision=3, subtype="PERCENTAGE",
        description="Stop once no point moves more than this share of an edge in each of 5 "
                    "iterations in a row: the shape no longer changes visibly, so the keys end "
                    "where the motion ends (0: run to Max Iterations or the Tolerance)",
    )
    refine: BoolProperty(
        name="Refine When Jammed", default=True,
        description="Split every edge in two (the same curve, twice the points) when the curve "
                    "is too coarse for its shape or its strands jam during the run, and go on; "
                    "the whole animation is keyed at the final point count. Off: such a curve "
                    "is refused or the run stops",
    )
    max_edges: IntProperty(
        name="Max Edges", default=0, min=0, soft_max=20000,
        description="Refine no further than this many edges (0: four times the start's, at "
                    "least 2000, within what a run here takes)",
    )
    # Keyframes
    frame_start: IntProperty(
        name="Start Frame", default=1,
        description="Frame of the start shape; iterate k is keyed k frames later",
    )
    keyframe_stride: IntProperty(
        name="Keyframe Every", default=1, min=1, soft_max=100,
        description="Keyframe every this many iterates (the last one always); 1 keeps the "
                    "guarantee that in-between frames never pass the curve through itself",
    )
    # Advanced
    restarts: IntProperty(
        name="Restarts", default=0, min=0, soft_max=10,
        description="After the flow converged, relax this many nudged copies of the result "
                    "(a small random smooth push) and keep the lowest energy: a way off a "
                    "symmetric shape the flow settled on. Each costs about a run",
    )
    seed: IntProperty(
        name="Seed", default=0, min=0,
        description="Seed of the restarts' nudges (the same seed, the same result)",
    )
    method: EnumProperty(
        name="Method", default=labels.DEFAULT_METHOD,
        items=[(key, label, desc) for key, label, desc in labels.METHODS],
        description="Optimizer of the paper's comparison; Automatic picks the faster of the "
                    "two exact ones for the curve. The three penalty methods let edge "
                    "lengths stretch a little and the barycenter drift",
    )
    penalty: FloatProperty(
        name="Penalty α", default=labels.DEFAULT_PENALTY, min=0.0, soft_min=1.0, soft_max=1e7,
        precision=1,
        description="Penalty methods only: weight α of the edge-stretch penalty "
                    "α Σ l0 log(l/l0)² (curve scaled to length 1). Larger keeps the edge "
                    "lengths closer to their start; must be positive",
    )
    engine: EnumProperty(
        name="Engine", default=labels.DEFAULT_ENGINE,
        items=[(key, label, desc) for key, label, desc in labels.ENGINES],
        description="How the energy and its gradient are evaluated: exactly over every pair "
                    "of edges, or by the Barnes–Hut tree (large curves)",
    )
    theta: FloatProperty(
        name="Theta", default=labels.DEFAULT_THETA, min=0.0, max=2.0, soft_max=1.0,
        precision=3,
        description="Tree engine only: admissibility θ of the far field of the energy and its "
                    "gradient, in (0, 2); 0: the energy's own (" + labels.THETA_TEXT + "). "
                    "Smaller is more accurate and slower",
    )
    initial_step: FloatProperty(
        name="Initial Step", default=1.0, min=1e-12, precision=4,
        description="First trial step size of the line search (trust region: initial radius, "
                    "relative to the gradient norm)",
    )
    armijo: FloatProperty(
        name="Armijo Constant", default=0.5, min=1e-6, max=0.999, precision=3,
        description="Sufficient-decrease constant σ of the explicit projected gradient's line "
                    "search (the paper's 1/2; also Automatic on unknots; the other "
                    "methods use their own)",
    )
    growth: FloatProperty(
        name="Step Growth", default=8.0, min=1.0, soft_max=10.0,
        description="Largest factor by which the step may grow from one iteration to the next "
                    "(explicit projected gradient, also Automatic on unknots; the "
                    "first trial is also kept below 2/3 of the first contact)",
    )
    backproject_iter: IntProperty(
        name="Back-projection Iterations", default=10, min=1, max=100,
        description="Newton iterations that restore the constraints after each step (methods "
                    "with exact constraints; the tree engine's hs takes a fifth more, its steps "
                    "being in a banded metric)",
    )
    # an exponent, not a float: a number field shows at most six decimals, so 1e-10 read
    # "0.000000" (and the property stores single precision anyway)
    backproject_digits: IntProperty(
        name="Back-projection Digits", default=10, min=2, max=14,
        description="Back-projection stops once every constraint holds to 10^-digits "
                    "(relative edge length; methods with exact constraints)",
    )
    keep_edge_lengths: BoolProperty(
        name="Keep Edge Lengths", default=True,
        description="Constrain every edge to keep its length (the curve's length is fixed); "
                    "the penalty methods penalize stretching instead",
    )
    keep_barycenter: BoolProperty(
        name="Keep Barycenter", default=True,
        description="Constrain the barycenter so the curve does not drift (not with the "
                    "penalty methods)",
    )
    keep_thickness: BoolProperty(
        name="Keep Thickness", default=False,
        description="Keep the rendered tubes apart, not only the centre lines: the curves' "
                    "bevel (Object Data ▸ Geometry ▸ Bevel ▸ Depth) is a radius the run keeps "
                    "between strands and from obstacles and the container (the methods that "
                    "keep edge lengths; Untangle Cables and Pack in Volume turn it on)",
    )
    push_apart: BoolProperty(
        name="Push Apart First", default=False,
        description="With Keep Thickness: a start whose tubes already meet is not refused; the "
                    "run keeps the tubes it allows and thickens them as the flow pushes the "
                    "strands apart, until they reach the bevel",
    )
    # Pins and obstacles (scene_constraints)
    pin_selected: BoolProperty(
        name="Pin Selected Points", default=False,
        description="Keep the points selected in Edit Mode exactly where they are (projected "
                    "and implicit gradient, trust region; the penalty methods refuse pins)",
    )
    pin_tangents: BoolProperty(
        name="Pin Tangents", default=False,
        description="Also keep the two neighbours of each pinned point, so that the curve "
                    "leaves it in the same directions",
    )
    obstacles: PointerProperty(
        type=bpy.types.Collection, name="Obstacles",
        description="Mesh objects of this collection repel the curve, which never passes "
                    "through them (as shown: modifiers applied)",
    )
    obstacle_weight: FloatProperty(
        name="Obstacle Weight", default=1.0, min=0.0, soft_max=10.0,
        description="Weight of the obstacles' (and the container's) repulsion beside the "
                    "curve's own energy (0: no repulsion, the curve is only stopped at them)",
    )
    container: PointerProperty(
        type=bpy.types.Object, name="Container",
        poll=lambda _settings, o: o.type == "MESH",
        description="A closed mesh object the curve stays inside (as shown: modifiers "
                    "applied); the curve must start inside it",
    )
    # Length growth (core: length_target=, length_growth=)
    use_length_target: BoolProperty(
        name="Grow Length", default=False,
        description="Grow the curve's total length during the run, a little every iteration, "
                    "to Length Target, then hold it (curve packing: with a Container the curve "
                    "folds to fill it). Runs on the projected gradient (Automatic picks it)",
    )
    length_target: FloatProperty(
        name="Length Target", default=10.0, min=0.0, soft_min=0.01, subtype="DISTANCE",
        description="Total length to grow to, in object units (of all splines together; at "
                    "least the curve's length at the start)",
    )
    length_growth: FloatProperty(
        name="Growth per Iteration", default=1.0, min=0.0, soft_min=0.01, soft_max=10.0,
        precision=2, subtype="PERCENTAGE",
        description="How much longer the curve gets per iteration, in percent (less where the "
                    "room runs out: a growth that would touch the curve itself, an obstacle or "
                    "the container is made smaller); must be above 0",
    )
    use_energy_target: BoolProperty(
        name="Energy Target", default=False,
        description="Stop once the energy is at or below a value",
    )
    energy_target: FloatProperty(
        name="Target", default=4.5, min=4.0,
        description="Energy at which to stop (4 is the round circle's)",
    )
    max_seconds: FloatProperty(
        name="Time Limit", default=0.0, min=0.0, subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE",
        description="Stop after this many seconds (0: no limit)",
    )
    # Live state of a running flow (written by the modal operator)
    running: BoolProperty(name="Running", default=False, options={"SKIP_SAVE"})
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype="FACTOR",
                            options={"SKIP_SAVE"})
    live_energy: FloatProperty(name="Energy", default=0.0, options={"SKIP_SAVE"})
    live_iteration: IntProperty(name="Iteration", default=0, options={"SKIP_SAVE"})
    # Live (blender.live): whether it runs, the record toggle, the panel's Finish
    live: BoolProperty(name="Live", default=False, options={"SKIP_SAVE"})
    live_stop: BoolProperty(name="Finish Live", default=False, options={"SKIP_SAVE"})
    live_record: BoolProperty(
        name="Record", default=False,
        description="Live: key every state of the live run on the curves when it ends (and "
                    "the moved obstacles' transforms), from the current frame on: the live "
                    "run becomes an animation in which nothing passes through anything")
    live_grow: FloatProperty(
        name="Grow", default=1.0, min=1.0, max=100.0, soft_max=4.0, precision=2,
        description="Live: the curves' total length as a multiple of their length when Live "
                    "began; drag it while Live runs and they grow towards it (or shrink back) "
                    "by Growth per Iteration, every step tested for contact",
        options={"SKIP_SAVE"})
    # Read-only statistics of the last run
    last_object: StringProperty(name="Object", get=_stat("object", ""))
    last_iterations: IntProperty(name="Iterations", get=_stat("iterations", 0))
    last_energy_start: FloatProperty(name="Start Energy", get=_stat("energy_start", 0.0))
    last_energy_end: FloatProperty(name="Final Energy", get=_stat("energy_end", 0.0))
    last_seconds: FloatProperty(name="Seconds", get=_stat("seconds", 0.0))
    last_message: StringProperty(name="Stopped Because", get=_stat("message", ""))
    last_keyframes: IntProperty(name="Keyed Frames", get=_stat("keyframes", 0))
    last_method: StringProperty(name="Method", get=_stat("method", ""))
    last_engine: StringProperty(name="Engine", get=_stat("engine", ""))
    last_type: StringProperty(name="Knot Type", get=_stat("type", ""))
    last_refined: StringProperty(name="Refined", get=_stat("refined", ""))
    last_energy_name: StringProperty(name="Energy Name",
                                     get=_stat("energy_name", labels.DEFAULT_ENERGY))
    last_energy_row: StringProperty(name="Energy Row", get=_stat("energy_row", "Energy"))
    # Notation typed for Add from Notation (braid word or PD code)
    notation: StringProperty(
        name="Notation", default="1 -2 1 -2",
        description="A braid word (1 -2 1 -2: σ1 σ2⁻¹ σ1 σ2⁻¹, σi a positive crossing; also "
                    "[1,-2,1,-2], {3, {1,-2,1,-2}}) or a PD code ([[1,5,2,4],[3,1,4,6],"
                    "[5,3,6,2]], PD[X[…], …], or Knoodle's rows of five)",
    )

    def store_run(self, obj_name: str, iterations: int, energy_start: float, energy_end: float,
                  seconds: float, message: str, keyed: int,
                  method: str = labels.DEFAULT_METHOD, engine: str = "",
                  knot_type: str = "", refined: str = "",
                  energy_name: str = labels.DEFAULT_ENERGY, energy_row: str = "Energy") -> None:
        """Record the statistics of a finished run (shown read-only in the panel)."""
        self["_stats"] = {
            "object": obj_name, "iterations": int(iterations),
            "energy_start": float(energy_start), "energy_end": float(energy_end),
            "seconds": float(seconds), "message": message, "keyframes": int(keyed),
            "method": method, "engine": engine, "type": knot_type, "refined": refined,
            "energy_name": energy_name, "energy_row": energy_row,
        }


for _record, _p in labels.ENERGY_PARAMETERS:  # α, β, Stiffness, ...: from the core's records
    MoebiusSettings.__annotations__[_p.setting] = FloatProperty(
        name=_p.label, default=_p.default, min=_p.minimum, soft_max=_p.soft_max,
        precision=_p.precision, description=_p.help)

classes = (MoebiusSettings,)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.moebius = bpy.props.PointerProperty(type=MoebiusSettings)


def unregister() -> None:
    del bpy.types.Scene.moebius
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
