"""The Energy menu: a flow of the tangent-point energy keyed like a Möbius one, the keyed energy
saying which it is; its exponents checked before any work; the command line's --energy."""

import importlib

import bpy
import numpy as np
import pytest
from bpy_helpers import points_at, scene_state


@pytest.fixture
def knot(scene, mb):
    bpy.ops.moebius.add_knot(kind="3_1", edges=90)
    return bpy.context.active_object


@pytest.mark.lines
def test_tangent_point_flow_is_keyed_with_its_name(scene, mb, core, knot):
    s = scene.moebius
    s.energy, s.max_iterations, s.tolerance = "tangent_point", 4, 0.0
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert knot[mb.ENERGY_NAME_PROP] == "tangent_point(2, 4.5)"  # the default exponents
    assert s.last_energy_name == "tangent_point(2, 4.5)"  # the Last Run box's "TP (2, 4.5)"
    assert "Tangent-point" in knot.id_properties_ui(mb.ENERGY_PROP).as_dict()["description"]
    frames = mb.keyed_frames(knot)
    assert frames == [1, 2, 3, 4, 5]
    keyed = []
    for f in (1, 5):
        scene.frame_set(f)
        keyed.append(knot[mb.ENERGY_PROP])
        # (2, 4.5) scales as λ^-0.5: the keyed value is the energy of the frame's curve scaled
        # to total length 1
        P = points_at(knot, f)
        P = P / np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).sum()
        assert keyed[-1] == pytest.approx(core.energy(P, energy="tangent_point"), rel=1e-6)
    assert keyed[1] < keyed[0]
    # the same flow as the core run with the same options
    ref = core.relax(points_at(knot, 1), max_iter=4, tol=0.0, energy="tangent_point",
                     method="projected_gradient_implicit", target_lengths="keep")
    np.testing.assert_allclose(points_at(knot, 5), ref.x, atol=1e-5)


def test_continue_with_another_energy_is_refused(scene, mb, knot):
    s = scene.moebius
    s.energy, s.max_iterations = "tangent_point", 2
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    s.energy = "moebius"
    before = scene_state()
    with pytest.raises(RuntimeError, match=r"tangent_point\(2, 4.5\) energy.*Clear Flow"):
        bpy.ops.moebius.relax(append=True)
    assert scene_state() == before


def test_gradient_fields_are_the_chosen_energys(scene, mb, core, knot):
    # Show Gradients drew the Möbius energy's fields whatever the Energy menu said
    s = scene.moebius
    s.energy, s.tp_alpha, s.tp_beta = "tangent_point", 2.0, 4.0
    assert bpy.ops.moebius.show_gradient(l2=False, length=0.2) == {"FINISHED"}
    P = mb.curve_polygons(knot)[0]
    for metric in ("hs_pure", "hs"):
        arrows = bpy.data.objects[f"{knot.name}.grad.{metric}"]
        assert arrows["moebius_gradient_energy"] == "tangent_point(2, 4)"
        V = np.array([v.co[:] for v in arrows.data.vertices])
        D = V[90:] - V[:90]
        G = core.sobolev_gradient(P, metric, energy="tangent_point", alpha=2, beta=4)
        np.testing.assert_allclose(D, arrows["moebius_arrow_scale"] * G,
                                   atol=1e-5 * np.abs(D).max())
        M = core.sobolev_gradient(P, metric)
        assert np.abs(G / np.abs(G).max() - M / np.abs(M).max()).max() > 1e-2
    # redrawn after a relaxation: still the tangent-point energy's, at the relaxed shape
    s.energy, s.max_iterations, s.tolerance = "moebius", 2, 0.0
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    P = mb.curve_polygons(knot)[0]
    arrows = bpy.data.objects[f"{knot.name}.grad.hs"]
    V = np.array([v.co[:] for v in arrows.data.vertices])
    G = core.sobolev_gradient(P, "hs", energy="tangent_point", alpha=2, beta=4)
    np.testing.assert_allclose(V[90:] - V[:90], arrows["moebius_arrow_scale"] * G,
                               atol=1e-5 * np.abs(V[90:] - V[:90]).max())


@pytest.mark.parametrize("alpha, beta, word", [(2.0, 5.5, "beta"), (0.5, 2.2, "beta")])
def test_bad_exponents_leave_the_scene(scene, mb, knot, alpha, beta, word):
    s = scene.moebius
    s.energy, s.tp_alpha, s.tp_beta = "tangent_point", alpha, beta
    before = scene_state()
    with pytest.raises(RuntimeError, match=word):
        bpy.ops.moebius.relax()
    assert scene_state() == before


def test_exponents_reach_the_run_only_for_the_tangent_point_energy(scene, mb):
    s = scene.moebius
    s.tp_alpha, s.tp_beta = 3.0, 6.0
    assert "alpha" not in mb.relax_settings(s)  # Möbius: no exponents passed
    s.energy = "tangent_point"
    kw = mb.relax_settings(s)
    assert (kw["energy"], kw["alpha"], kw["beta"]) == ("tangent_point", 3.0, 6.0)


def test_the_metric_order_shown_follows_the_energy(scene, mb):
    from importlib import import_module

    labels = import_module(mb.__name__ + ".labels")
    s = scene.moebius
    shown = lambda: labels.metric_order_text(s.energy, s.tp_alpha, s.tp_beta)  # noqa: E731
    s.tp_alpha, s.tp_beta = 3.0, 6.0
    assert shown() == "s = 3/2"  # Möbius: the paper's order, whatever the exponents say
    s.energy = "tangent_point"
    assert shown() == "s = 5/3"  # (β − 1)/α
    s.tp_alpha, s.tp_beta = 2.0, 4.5
    assert shown() == "s = 7/4"
    s.tp_alpha, s.tp_beta = 2.5, 4.2
    assert shown() == "s = 1.28"  # not a small fraction
    s.tp_beta = 7.0  # outside (α + 1, 2α + 1): the panel says so instead of an order
    with pytest.raises(ValueError, match="beta"):
        shown()
    assert all("W^{s,2}" in label for key, label, _ in labels.METRICS if key.startswith("hs"))


def test_cli_energy(scene, mb, capfd):
    from importlib import import_module

    cli = import_module(mb.__name__ + ".cli")
    capfd.readouterr()
    rc = cli.main(["--knot", "3_1", "--edges", "60", "--max-iterations", "2",
                   "--energy", "tangent_point", "--alpha", "3", "--beta", "6"])
    assert rc == 0
    assert "tangent_point(3, 6) energy" in capfd.readouterr().out
    assert bpy.context.active_object[mb.ENERGY_NAME_PROP] == "tangent_point(3, 6)"
    assert cli.main(["--knot", "3_1", "--energy", "tangent_point", "--beta", "9"]) == 1
    assert "beta" in capfd.readouterr().err


def test_menus_and_sliders_are_the_cores_records(scene, mb, core):
    # the Energy and Metric menus, the parameters' sliders and the command line's choices are
    # read from the core's records: a record added there appears here
    labels = importlib.import_module(mb.__name__ + ".labels")
    from_core = core.energies.choice.RUN_ENERGY_NAMES
    assert tuple(k for k, _, _ in labels.ENERGIES) == from_core
    props = scene.moebius.bl_rna.properties
    assert tuple(i.identifier for i in props["energy"].enum_items) == from_core
    metrics = tuple(core.metrics.records.METRIC_RECORDS)
    assert tuple(k for k, _, _ in labels.METRICS) == metrics
    assert set(metrics) == set(core.METRICS)
    assert tuple(i.identifier for i in props["metric"].enum_items) == metrics
    for record in core.energies.ENERGIES.values():
        for p in record.options:  # α, β, Stiffness
            assert props[p.setting].default == pytest.approx(p.default)
            assert props[p.setting].name == p.label
    cli = importlib.import_module(mb.__name__ + ".cli")
    text = cli._parser().format_help()
    assert "--stiffness" in text and "--alpha" in text and "--beta" in text


def test_a_tangent_point_run_from_the_defaults_gets_its_own_theta(scene, mb, core, knot):
    # the panel's θ passed the Möbius tree's 0.175 to every energy; 0 now means the energy's own
    s = scene.moebius
    s.energy, s.engine, s.max_iterations = "tangent_point", "tree", 1
    assert s.theta == 0.0
    assert mb.relax_settings(s)["theta"] is None
    run = mb.ObjectRelaxation(knot, **mb.relax_settings(s))
    assert run.run.engine.theta == core.energies.ENERGIES["tangent_point"].default_theta == 0.5
    s.energy = "moebius"
    run = mb.ObjectRelaxation(knot, **mb.relax_settings(s))
    assert run.run.engine.theta == core.energies.ENERGIES["moebius"].default_theta == 0.175
    s.theta = 0.3  # a typed θ is every energy's
    assert mb.ObjectRelaxation(knot, **mb.relax_settings(s)).run.engine.theta == 0.3


def test_stiffness_slider_reaches_the_run(scene, mb, core, knot):
    s = scene.moebius
    assert "stiffness" not in mb.relax_settings(s)  # 0: no bending term at all
    s.stiffness, s.max_iterations, s.tolerance = 0.5, 2, 0.0
    assert mb.relax_settings(s)["stiffness"] == 0.5
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert knot[mb.ENERGY_NAME_PROP] == "moebius + bending(0.5)"
    assert s.last_energy_row == "Energy + 0.5 bend"
    assert "bending" in knot.id_properties_ui(mb.ENERGY_PROP).as_dict()["description"]
    cli = importlib.import_module(mb.__name__ + ".cli")
    assert cli.main(["--knot", "3_1", "--edges", "60", "--max-iterations", "1",
                     "--stiffness", "0.2"]) == 0
    assert cli.main(["--knot", "3_1", "--edges", "60", "--stiffness", "-1", "--no-relax"]) == 1
