"""The operating point: statics under the scene's mean loads (issue 22, item 1), and the slip
margins by the capstan law (item 3).

Checks that could fail: each free pulley's moment balance (the span forces on the pulleys differ
by exactly M / R across a loaded pulley, the idler's by its bearing drag), the power balance of
the steady motion (drive torque times its speed plus every load's power is zero), both
fidelities agreeing, the gradient of the operating point against finite differences, the
unloaded state kept beside it, the capstan demand against Euler-Eytelwein written out, the
ribbed belt's wedge on front- but not back-side pulleys, the command's outputs, and a published
case (Shigley's flat-belt Example 17-1: tensions, centrifugal tension and friction development).
"""

from __future__ import annotations

import json
import math
import re

import equinox as eqx
import jax
import numpy as np
import pytest

from beltjax import drive, friction, parameters, statics
from beltjax.cli import main
from beltjax.scene import load_scene, loads_scene

from _creep_profile import belt_held, creeping, gripping
from _scenes import SCENES, scene_text
from _scenes import loaded_two_pulley as _two_pulley  # M_ALT on the alternator by default

M_ALT = 6.0  # N m on the alternator (CCW: against the clockwise travel)


def _tensioner(drag: float = 0.02) -> str:
    txt = scene_text("sim_tensioner_installation.toml")
    txt = txt.replace("speed_rpm = 0.0", "speed_rpm = 1500.0", 1)
    txt = txt.replace('effects = ["belt_damping", "tensioner_damping"]', 'effects = ["transport", "bearing_damping"]')
    txt = txt.replace("CA = 3.33 ", "CA = 0.0 ").replace("damping = 0.1 ", "damping = 0.0 ")
    txt = re.sub(r"(?ms)^\[initial\].*?(?=^\[)", "", txt)
    txt = txt.replace("inertia = 1.7019e-3        # kg m^2", f"inertia = 1.7019e-3\nbearing_damping = {drag}", 1)
    return txt + f'\n[[torque]]\npulley = "alternator"\nmean_Nm = {M_ALT}\n'


@pytest.fixture(scope="module", params=["rotational", "ancf"])
def two_pulley(request):
    sc = loads_scene(_two_pulley(request.param))
    return sc, statics.analyse_statics(sc)


def test_moment_balance_and_power_of_a_loaded_two_pulley_drive(two_pulley):
    sc, r = two_pulley
    assert r.state == "operating point" and r.loads_Nm == {"alternator": M_ALT}
    R_alt = float(sc.pulley("alternator").radius)
    R_crank = float(sc.pulley("crank").radius)
    F = r.span_forces_N  # crank-alternator (arrives at the alternator), alternator-crank (leaves it)
    # the alternator turns clockwise: the span leaving it is the tight one (it pulls the alternator round)
    assert F[1] - F[0] == pytest.approx(M_ALT / R_alt, rel=1e-9)
    # power: the drive torque at the crank's speed balances the load at the alternator's (no losses)
    v = r.speed_m_s
    w_crank, w_alt = -v / R_crank, -v / R_alt  # clockwise
    assert r.drive_torque_Nm * w_crank + M_ALT * w_alt == pytest.approx(0.0, abs=1e-9 * M_ALT * abs(w_alt))
    # the unloaded state is kept beside it, equal tensions
    un = r.unloaded
    assert un["state"] == "unloaded" and un["drive_torque_Nm"] == pytest.approx(0.0, abs=1e-8)
    assert np.allclose(un["span_tensions_N"], 400.0, rtol=1e-9)
    # fixed centres and equal span lengths: the belt's length is kept, so the tensions move apart evenly
    assert np.mean(r.span_tensions_N) == pytest.approx(400.0, rel=2e-3)


def test_both_fidelities_give_one_operating_point():
    a = statics.analyse_statics(loads_scene(_two_pulley("rotational")))
    b = statics.analyse_statics(loads_scene(_two_pulley("ancf")))
    assert np.allclose(a.span_tensions_N, b.span_tensions_N, rtol=1e-6)
    assert a.drive_torque_Nm == pytest.approx(b.drive_torque_Nm, rel=1e-9)


def test_the_unloaded_state_on_request_and_without_loads():
    sc = loads_scene(_two_pulley("rotational"))
    r = statics.analyse_statics(sc, loaded=False)
    assert r.state == "unloaded" and r.unloaded is None and np.allclose(r.span_tensions_N, 400.0, rtol=1e-9)
    r0 = statics.analyse_statics(loads_scene(scene_text("two_pulley_T400.toml")))
    assert r0.state == "unloaded" and r0.loads_Nm == {}


def test_tensioner_drive_with_bearing_drag_balances_moments_and_power():
    sc = loads_scene(_tensioner(drag=0.02))
    r = statics.analyse_statics(sc)
    v = r.speed_m_s
    order = sc.route.order
    senses = np.asarray(sc.route.senses)
    R = {"crank": 0.1015, "alternator": 0.0375, "tensioner": 0.037}
    w = {k: senses[i] * v / R[k] for i, k in enumerate(order)}
    drag = -0.02 * w["alternator"]
    assert r.loads_Nm["alternator"] == pytest.approx(M_ALT + drag, rel=1e-12)
    # moment balance of the alternator and of the (drag-free) idler: span forces on the pulleys
    F = dict(zip(r.span_names, r.span_forces_N))
    s_alt = senses[order.index("alternator")]
    assert s_alt * R["alternator"] * (F["alternator-crank"] - F["tensioner-alternator"]) == pytest.approx(
        -(M_ALT + drag), rel=1e-9)
    assert F["crank-tensioner"] == pytest.approx(F["tensioner-alternator"], rel=1e-9)
    # power balance, bearing drag included
    power = r.drive_torque_Nm * w["crank"] + (M_ALT + drag) * w["alternator"]
    assert power == pytest.approx(0.0, abs=1e-8 * abs(M_ALT * w["alternator"]))
    # the arm moved: the tight side now pulls the idler
    assert r.tensioner_angle_deg != pytest.approx(r.unloaded["tensioner_angle_deg"], abs=1e-3)


def test_operating_point_gradient_matches_finite_differences():
    """d(tight-side tension)/d(load) through the equilibrium's implicit differentiation."""
    sc = drive.canonical(loads_scene(_two_pulley("rotational")))
    v = float(drive.belt_speed(sc))

    def tight(m):
        s = eqx.tree_at(lambda x: x.torques[0].mean_Nm, sc, m)
        out, _ = statics._statics_core(s, v, loaded=True)
        return out["tensions"][1]

    m0 = jax.numpy.asarray(M_ALT)
    g = float(jax.grad(tight)(m0))
    h = 1e-3
    fd = (float(tight(m0 + h)) - float(tight(m0 - h))) / (2 * h)
    assert g == pytest.approx(fd, rel=1e-6)
    R = float(sc.pulley("alternator").radius)
    assert g == pytest.approx(1 / (2 * R), rel=0.02)  # half the load on each span: the belt grips (arcs kept)


def test_operating_point_gradient_in_the_friction_coefficient():
    """The running belt's sliding arcs, ln(F_out / F_in) / mu', set how much slack belt the arcs
    hold, so the operating point's tension level depends on mu' (a little): its derivative
    through the equilibrium against finite differences; the tensions fall towards the
    no-sliding limit (mu' -> infinity) as mu' rises."""
    sc = drive.canonical(loads_scene(creeping(_two_pulley("rotational", extra_belt="friction_coefficient = 0.4"))))
    v = float(drive.belt_speed(sc))

    def tight(mu):
        s = eqx.tree_at(lambda x: x.belt.friction_coefficient, sc, mu)
        out, _ = statics._statics_core(s, v, loaded=True)
        return out["tensions"][1]

    mu0 = jax.numpy.asarray(0.4)
    g = float(jax.grad(tight)(mu0))
    h = 1e-4
    fd = (float(tight(mu0 + h)) - float(tight(mu0 - h))) / (2 * h)
    assert g == pytest.approx(fd, rel=1e-5) and g < 0


def test_capstan_demand_and_the_wedge():
    txt = _two_pulley("rotational", extra_belt="friction_coefficient = 0.25\ngroove_angle_deg = 40.0")
    sc = loads_scene(txt)
    r = statics.analyse_statics(sc)
    F = r.span_forces_N
    for i, name in enumerate(sc.route.order):
        wrap = math.radians(r.friction[name]["wrap_deg"])
        need = abs(math.log(F[i] / F[i - 1])) / wrap  # Euler-Eytelwein, centrifugal tension out
        assert r.friction[name]["friction_needed"] == pytest.approx(need, rel=1e-12)
        have = 0.25 / math.sin(math.radians(20.0))  # the ribs' wedge
        assert r.friction[name]["friction_available"] == pytest.approx(have, rel=1e-12)
        assert r.friction[name]["slip_margin"] == pytest.approx(1 - need / have, rel=1e-12)
    # a back-side pulley runs on the belt's flat back: no wedge
    sc2 = loads_scene(_tensioner().replace("rhoA = 0.12101 ", "friction_coefficient = 0.3\ngroove_angle_deg = 40.0\n"
                                                             "rhoA = 0.12101 "))
    mu = friction.effective_coefficients(sc2)
    order = sc2.route.order
    assert mu[order.index("tensioner")] == pytest.approx(0.3)
    assert mu[order.index("alternator")] == pytest.approx(0.3 / math.sin(math.radians(20.0)))


def test_a_pulley_that_would_slip_is_reported(tmp_path, capsys):
    txt = _two_pulley("rotational", torque=15.0, extra_belt="friction_coefficient = 0.3")
    path = tmp_path / "slip.toml"
    path.write_text(txt)
    assert main(["statics", str(path), "--out", str(tmp_path / "out")]) == 0
    out, err = capsys.readouterr()
    assert "operating point" in out and "SLIPS" in out
    assert re.search(r"warning: the belt would slip at the operating point \(crank needs mu' = [\d.]+, has 0\.3", err)
    data = json.loads((tmp_path / "out" / "statics.json").read_text())
    assert data["state"] == "operating point" and set(data["slipping"]) == {"crank", "alternator"}
    assert data["unloaded"]["state"] == "unloaded" and data["drive_torque_Nm"] < 0
    assert main(["statics", str(path), "--out", str(tmp_path / "out2"), "--unloaded"]) == 0
    data = json.loads((tmp_path / "out2" / "statics.json").read_text())
    assert data["state"] == "unloaded" and data["slipping"] == [] and "unloaded" not in data


def test_a_load_the_belt_cannot_carry_is_a_slack_span():
    """A load beyond what the installation tension carries slackens the slack side: one line."""
    from beltjax.errors import BeltjaxError

    with pytest.raises(BeltjaxError, match=r"span crank-alternator would go slack at the operating point"):
        statics.analyse_statics(loads_scene(_two_pulley("rotational", torque=40.0)))


@pytest.mark.parametrize("mean", [5e4, -1e5])
def test_loads_that_wind_the_arm_round_are_refused(mean, tmp_path, capsys):
    """A load the belt cannot carry whose equations still have a solution, with the tensioner arm
    wound turns round and the spans stretched many times over: refused (one line naming the
    loads, exit 2, no files), from the command line and the Python API alike."""
    from beltjax.errors import BeltjaxError

    path = tmp_path / "wound.toml"
    path.write_text(FEAD.replace('pulley = "alternator"\nmean_Nm = 3.0', f'pulley = "alternator"\nmean_Nm = {mean}'))
    assert main(["statics", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("beltjax: error: torque: the tensioner arm would turn to "), err
    assert "more than 180 deg" in err and not (tmp_path / "out").exists()
    with pytest.raises(BeltjaxError, match="tensioner arm would turn to") as exc:
        statics.analyse_statics(load_scene(path))
    assert str(exc.value) in err


def test_operating_faults_in_closed_form():
    """The one test of a state past what a belt carries (statics, sweeps, responses, optimisation):
    a span's strain over 2 % of its unstretched length, the arm turned over half a turn; a state
    that only turns a pulley stretches nothing."""
    sc = loads_scene(_tensioner())
    inst = statics.install_compiled(sc)
    faults, strains = jax.jit(statics.operating_faults), jax.jit(statics.operating_strains)
    qi = np.zeros(drive.n_independent(sc))
    base = faults(sc, qi, inst)
    assert not any(bool(v) for v in base.values())
    assert float(np.max(np.abs(strains(sc, qi, inst) - (float(inst.stretch) - 1)))) < 1e-12
    arm = [i for i in range(len(qi)) if float(drive.angles_and_arm(np.eye(len(qi))[i], sc, inst)[1] - inst.arm_angle) != 0]
    assert len(arm) == 1
    q = np.zeros(len(qi))
    q[arm[0]] = 1.01 * math.pi  # the arm turned just over half a turn (its spans stretch too)
    assert bool(faults(sc, q, inst)["arm_wound"])
    s0 = np.asarray(strains(sc, qi, inst))
    per_rad = np.array([np.asarray(strains(sc, e, inst)) - s0 for e in np.eye(len(qi))])
    per_rad[arm[0]] = 0.0  # a pulley's turn slides the belt along its spans: linear in its angle
    k, j = np.unravel_index(np.argmax(per_rad), per_rad.shape)
    for strain, over in ((0.019, False), (0.021, True)):  # pulley k turned to stretch span j this far
        q = np.zeros(len(qi))
        q[k] = (strain - s0[j]) / per_rad[k, j]
        assert float(strains(sc, q, inst)[j]) == pytest.approx(strain, rel=1e-9)
        assert bool(faults(sc, q, inst)["span_overstretched"]) is over


def test_a_loaded_drive_past_its_critical_speed_is_told_so_not_blamed_on_its_loads():
    """Loaded and far past its critical speed, the tensioner drive's operating point has slack
    spans; the cause is the speed (its unloaded state is past the critical speed too), and the
    one line says so, with the critical speed, rather than blaming the loads."""
    from beltjax.errors import BeltjaxError

    sc = loads_scene(_tensioner().replace("speed_rpm = 1500.0", "speed_rpm = 30000.0", 1))
    with pytest.raises(BeltjaxError, match=r"is past the critical speed 91\.\d+ m/s") as e:
        statics.analyse_statics(sc)
    assert "slack" not in str(e.value) and "loads" not in str(e.value)


def test_capstan_limit_of_a_two_pulley_drive_in_closed_form():
    """The largest torque a two-pulley drive transmits: F_t / F_s = exp(mu theta) on the smaller
    wrap and F_t + F_s = 2 F_0 (fixed centres, equal spans: the belt's length is kept), so
    M_max = 2 F_0 R tanh(mu theta / 2) with F_0 the installation tension less the centrifugal
    part.  Found on the operating point by bisection on the slip margin."""
    mu = 0.3

    def margin(m):
        r = statics.analyse_statics(loads_scene(_two_pulley("rotational", torque=m,
                                                            extra_belt=f"friction_coefficient = {mu}")))
        return min(v["slip_margin"] for v in r.friction.values()), r

    lo, hi = 1.0, 25.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if margin(mid)[0] > 0 else (lo, mid)
    _, r = margin(lo)
    sc = loads_scene(_two_pulley("rotational"))
    R = float(sc.pulley("alternator").radius)
    theta = math.radians(min(v["wrap_deg"] for v in r.friction.values()))
    F0 = float(np.mean(r.unloaded["span_forces_N"]))
    m_max = 2 * F0 * R * math.tanh(mu * theta / 2)
    assert lo == pytest.approx(m_max, rel=2e-3)
    assert min(r.friction, key=lambda k: r.friction[k]["slip_margin"]) == "alternator"  # the smaller wrap


def test_a_transient_under_steady_loads_starts_at_its_operating_point_and_reports_slip():
    """Rotational two-pulley drive, a lasting load and a pulse on top: the run starts at the
    operating point (the slip margins equal the statics' until the pulse), and the pulse that
    passes the capstan limit is reported, with the time it began."""
    from beltjax import transient
    from beltjax.span_flags import run_warnings

    txt = _two_pulley("rotational", extra_belt="friction_coefficient = 0.3\nCA = 2.0")
    txt = txt.replace('effects = ["transport"]', 'effects = ["transport", "belt_damping"]')
    st = statics.analyse_statics(loads_scene(txt))
    txt += '\n[[torque]]\npulley = "alternator"\nmean_Nm = 8.0\nt_start_s = 0.1\nt_end_s = 0.2\n'
    res = transient.simulate(loads_scene(txt), 0.3)
    t, m = res.t, res.channels["slip_margins"]
    assert res.columns["slip_margins"] == ["crank", "alternator"]
    before = t < 0.1
    steady = np.array([st.friction[k]["slip_margin"] for k in ("crank", "alternator")])
    assert np.max(np.abs(m[before] - steady)) < 1e-6
    assert np.allclose(res.channels["friction_needed"][before], [st.friction[k]["friction_needed"]
                                                                 for k in ("crank", "alternator")], atol=1e-6)
    rec = {r["pulley"]: r for r in res.meta["slipping_pulleys"]}
    assert set(rec) == {"crank", "alternator"}
    assert 0.1 <= rec["alternator"]["t_first_s"] < 0.11  # the pulse (and the ringing after it)
    assert rec["alternator"]["min_slip_margin"] < 0
    assert any("the belt would slip on 'alternator'" in w for w in run_warnings(res.meta))


FEAD = scene_text("fead_8pulley.toml")


def test_sweep_columns_of_the_operating_point(tmp_path, capsys):
    """A sweep of a loaded drive reports the operating point (tensions, drive torque, the arcs'
    friction and slip margins) case by case, equal to the statics of each case; a case that would
    slip is named in sweep.json and in a warning; one whose loads would stretch a span past 2 %
    (installed at 1.98 %) is flagged, as the statics refuse it."""
    from beltjax.errors import BeltjaxError

    sweep = tmp_path / "sweep.toml"
    sweep.write_text('outputs = ["statics"]\n[[grid]]\nparameter = "belt.static_tension"\n'
                     'values = [150.0, 300.0, 2370.0]\n')
    (tmp_path / "fead.toml").write_text(FEAD)
    assert main(["sweep", str(tmp_path / "fead.toml"), str(sweep), "--out", str(tmp_path / "out")]) == 0
    import csv

    rows = list(csv.DictReader(open(tmp_path / "out" / "sweep.csv")))
    assert [row["status"] for row in rows] == ["ok", "ok", "span_overstretched"]
    with pytest.raises(BeltjaxError, match=r"would stretch 2\.01\d % at the operating point"):
        statics.analyse_statics(loads_scene(FEAD.replace("static_tension = 300.0", "static_tension = 2370.0")))
    rows = rows[:2]
    for row in rows:
        sc = loads_scene(FEAD.replace("static_tension = 300.0", f"static_tension = {row['belt.static_tension']}"))
        r = statics.analyse_statics(sc)
        assert float(row["drive_torque_Nm"]) == pytest.approx(r.drive_torque_Nm, rel=1e-8)
        assert float(row["tension_crank-ac_N"]) == pytest.approx(r.span_tensions_N[0], rel=1e-8)
        for name, v in r.friction.items():
            assert float(row[f"slip_margin_{name}"]) == pytest.approx(v["slip_margin"], rel=1e-6, abs=1e-9)
        assert float(row["min_slip_margin"]) == pytest.approx(min(v["slip_margin"] for v in r.friction.values()))
    assert float(rows[0]["min_slip_margin"]) < 0 < float(rows[1]["min_slip_margin"])  # 150 N slips at the crank
    report = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert report["slipping"]["min_slip_margin"]["cases"] == [0]
    assert "WARNING: in 1 of 3 cases the belt would slip at the operating point" in capsys.readouterr().out


def test_optimize_with_a_minimum_slip_margin(tmp_path):
    """The lowest crank hub load (lowest installation tension) that keeps every arc's slip
    margin at 0.3: the constraint ends active, and the statics of the result agree."""
    (tmp_path / "fead.toml").write_text(FEAD)
    opt = tmp_path / "opt.toml"
    opt.write_text('steps = 150\nlearning_rate = 0.02\n[[variable]]\nparameter = "belt.static_tension"\nlower = 150\n'
                   'upper = 400\n[[objective]]\nkind = "hub_load"\npulley = "crank"\nweight = 0.001\n'
                   '[[constraint]]\nkind = "min_slip_margin"\nvalue = 0.3\n')
    assert main(["optimize", str(tmp_path / "fead.toml"), str(opt), "--out", str(tmp_path / "out")]) == 0
    data = json.loads((tmp_path / "out" / "optimize.json").read_text())
    assert data["all_constraints_satisfied"] and data["goal_met"]
    r = statics.analyse_statics(load_scene(tmp_path / "out" / "optimized_scene.toml"))
    margin = min(v["slip_margin"] for v in r.friction.values())
    assert 0.3 - 0.005 <= margin < 0.31  # active within the constraint's tolerance
    assert r.installation_tension_N < 300.0


def test_creep_speed_ratio_and_sliding_arc_by_classical_theory():
    """Below the capstan limit: the driven pulley's speed ratio is (1 + eps_slack) / (1 + eps_tight)
    (its rim runs with the slack belt arriving, the driver's with the tight one), and the belt
    slides over ln(F_tight / F_slack) / mu' of each wrap."""
    from beltjax import span

    mu = 0.4
    sc = loads_scene(_two_pulley("rotational", extra_belt=f"friction_coefficient = {mu}"))
    r = statics.analyse_statics(sc)
    EA = float(sc.belt.EA)
    lam_slack, lam_tight = (float(span.stretch_for_tension(T, EA)) for T in r.span_tensions_N)
    f = r.friction
    assert f["crank"]["creep_speed_loss"] == 0.0  # the drive pulley is the reference
    assert 1 - f["alternator"]["creep_speed_loss"] == pytest.approx(lam_slack / lam_tight, rel=1e-9)
    F = r.span_forces_N
    arc = math.degrees(math.log(F[1] / F[0]) / mu)
    assert f["crank"]["sliding_arc_deg"] == pytest.approx(arc, rel=1e-9)
    assert f["alternator"]["sliding_arc_deg"] == pytest.approx(arc, rel=1e-9)
    assert arc < min(v["wrap_deg"] for v in f.values())


def test_modes_are_about_the_operating_point():
    """Modal analysis, Campbell diagrams, sweeps and optimisation linearise about the operating
    point of a loaded drive (one pipeline, drive_modal.at_speed): its state is the statics'
    operating point, and the loads move the modes away from the unloaded state's."""
    from beltjax import drive_modal

    sc = drive.canonical(loads_scene(_tensioner(drag=0.02)))
    v = float(drive.belt_speed(sc))

    @jax.jit
    def both(s):
        a = drive_modal.at_speed(s, v)
        qi, inst, _ = statics.equilibrium(s, speed=v)  # unloaded
        return a.qi, a.freqs, drive_modal.frequencies_about(s, qi, inst, v)[1]

    qi, f, f0 = (np.asarray(x) for x in both(sc))
    assert np.allclose(qi, statics.analyse_statics(sc).qi, rtol=1e-9, atol=1e-12)
    assert np.all(np.isfinite(f)) and np.max(np.abs(f0 / f - 1)) > 1e-3


@pytest.mark.parametrize("name", ["two_pulley", "fead_8pulley.toml", "shigley_flat_belt.toml"])
def test_a_running_belt_keeps_its_length(name):
    """The running belt's compatibility (Rubin 2000), with ``belt_slip`` listed: the belt the
    spans and arcs hold, written out by classical creep theory, is the belt installed, to the
    first order of the model's kinematics in the strains (about 1e-6 of the length), on the
    two-pulley bench (6 N m), the eight-pulley drive (its arm settles where the belt's length
    holds; mu' on every arc) and Shigley's drive (sliding arcs of 68 deg).  The same fixed-centre
    drive whose belt grips (no ``belt_slip``) keeps its arcs as installed, and its operating
    point's belt is about 100 times further off (asked: more than 20 times; 1.5e-4 on the
    eight-pulley drive: benchmarks/running_belt_length.py): a loaded running belt's arcs are not as installed.  At speed
    without loads the running belt runs at one tension, its arcs' as its spans'.  (Where an arm
    swings by tens of degrees, the kinematic map, which keeps the belt's stretched length as the
    arm swings, adds R dwrap (eps_span - eps_arc) to this balance: 2e-5 of the length for a
    54 deg swing of the tensioner bench's arm.)"""
    txt = _two_pulley("rotational", extra_belt="friction_coefficient = 0.4") if name == "two_pulley" else scene_text(name)
    sc = loads_scene(creeping(txt))
    r = statics.analyse_statics(sc)
    L = float(r.inst.belt_length)
    assert abs(belt_held(sc, r) / L - 1) < 2e-6 and np.any(np.abs(np.asarray(r.inst.creep)) > 0)
    if name != "fead_8pulley.toml":  # (the fixed-centre drives: one 8-pulley statics compiled, not two)
        grips = loads_scene(gripping(txt))
        r0 = statics.analyse_statics(grips)
        assert abs(belt_held(grips, r0) / L - 1) > 2e-5
        assert abs(belt_held(grips, r0, arcs_as_installed=True) / L - 1) < 2e-6  # what the grip keeps
        assert np.all(np.asarray(r0.inst.creep) == 0)
    T = np.asarray(r.unloaded["span_tensions_N"])
    assert np.allclose(T, T[0], rtol=1e-9)


def test_published_flat_belt_drive_shigley_example_17_1():
    """A published slip check: Shigley's Mechanical Engineering Design, Example 17-1 (scenes/
    shigley_flat_belt.toml).  The book's numbers, from its inputs in its units: wrap on the 6 in
    driver pi - 2 asin((18 - 6) / (2 x 96)) = 3.0165 rad, torque T = 63025 H K_s n_d / n =
    742.8 lbf in, centrifugal tension F_c = w / g (V / 60)^2 = 25.6 lbf (w = 0.393 lbf/ft,
    V = 2749 ft/min), tight side F_1 = 420 lbf (the allowable), slack side F_2 = F_1 - 2 T / d =
    172.4 lbf, the initial tension F_i = (F_1 + F_2) / 2 - F_c = 270.6 lbf, friction development
    f' = ln((F_1 - F_c) / (F_2 - F_c)) / phi = 0.328 against f = 0.8.

    Installed as the book says (F_i + F_c: a fixed-centre belt keeps its stretch when it runs),
    the operating point must give the torque and F_1 - F_2 to 0.1 % and F_c to 0.5 % from the
    drive's geometry, masses and load alone.  The book's F_i holds the sum F_1 + F_2 as
    installed, which keeps the arcs' belt as installed; a running belt's arcs hold it at the
    tension it ran on with (test_a_running_belt_keeps_its_length), and this drive's large
    driven arc then holds more slack belt: both tensions rise by one delta > 0 (Rubin 2000: the
    classical compatibility underpredicts both).  Installed that delta lower, so that it runs at
    the book's mean, the drive must give F_1 and F_2 to 0.1 % and f' to the book's three digits."""
    LBF, IN = 4.4482216152605, 0.0254
    phi = math.pi - 2 * math.asin(12 / 192)
    T = 63025 * 15 * 1.25 * 1.1 / 1750  # lbf in
    w, V = 12 * 0.042 * 6 * 0.13, math.pi * 6 * 1750 / 12  # lbf/ft, ft/min
    assert (round(w, 3), round(V)) == (0.393, 2749)
    Fc = 0.393 / 32.17 * (2749 / 60) ** 2  # with the book's rounded w and V
    F1, F2 = 420.0, 420.0 - 2 * T / 6
    assert (round(phi, 4), round(T, 1), round(Fc, 1), round(F2, 1)) == (3.0165, 742.8, 25.6, 172.4)  # as printed
    sc = load_scene(SCENES / "shigley_flat_belt.toml")
    assert float(sc.belt.static_tension) / LBF == pytest.approx((F1 + F2) / 2, abs=0.05)  # F_i + F_c
    r = statics.analyse_statics(sc)
    f = r.friction["driver"]
    assert math.radians(f["wrap_deg"]) == pytest.approx(phi, abs=1e-4)
    assert -r.drive_torque_Nm / (LBF * IN) == pytest.approx(T, rel=1e-3)
    slack, tight = np.asarray(r.span_tensions_N) / LBF  # driver-driven leaves the driver: the slack side
    assert tight - slack == pytest.approx(F1 - F2, rel=1e-3)
    assert np.allclose((np.asarray(r.span_tensions_N) - np.asarray(r.span_forces_N)) / LBF, Fc, rtol=5e-3)
    delta = tight - F1
    assert delta > 0.01 * F2 and slack - F2 == pytest.approx(delta, abs=0.1)
    r = statics.analyse_statics(parameters.set_value(sc, "belt.static_tension", sc.belt.static_tension - delta * LBF))
    f = r.friction["driver"]
    slack, tight = np.asarray(r.span_tensions_N) / LBF
    assert tight == pytest.approx(F1, rel=1e-3) and slack == pytest.approx(F2, rel=1e-3)
    assert abs(f["friction_needed"] - 0.328) < 1e-3
    assert f["slip_margin"] == pytest.approx(1 - f["friction_needed"] / 0.8, rel=1e-12) and f["slip_margin"] > 0.5


def test_wraps_and_slip_margins_are_those_of_the_solved_arm_angle():
    """Under load the arm swings off its installed angle, turning the wraps of its idler and its
    neighbours: statics.json's wraps and the arcs' friction are those of the solved layout (equal
    to the tangent geometry at the solved arm angle), in the operating point and the unloaded state."""
    sc = loads_scene(_tensioner(drag=0.0).replace(f"mean_Nm = {M_ALT}", "mean_Nm = 20.0"))
    r = statics.analyse_statics(sc)
    order = sc.route.order
    for state, angle, wraps, arcs in ((r, r.tensioner_angle_deg, r.wrap_angles_deg, r.friction),
                                      (None, r.unloaded["tensioner_angle_deg"], r.unloaded["wrap_angles_deg"],
                                       r.unloaded["friction"])):
        exact = np.degrees(np.asarray(sc.geometry(np.radians(angle), check=False).wrap))
        got = np.array([wraps[k] for k in order])
        np.testing.assert_allclose(got, exact, rtol=0, atol=1e-9)
        np.testing.assert_allclose([arcs[k]["wrap_deg"] for k in order], exact, rtol=0, atol=1e-9)
    installed = np.degrees(np.asarray(r.inst.wrap))
    loaded = np.array([r.wrap_angles_deg[k] for k in order])
    assert np.max(np.abs(loaded - installed)) > 0.5  # the arm's swing turned them (else this tests nothing)
    F = dict(zip(r.span_names, r.span_forces_N))
    k = order.index("alternator")
    need = math.log(F["alternator-crank"] / F["tensioner-alternator"]) / math.radians(loaded[k])  # capstan law
    assert r.friction["alternator"]["friction_needed"] == pytest.approx(need, rel=1e-9)


def test_free_span_lengths_and_the_hybrid_models_end_node_note():
    """statics.json gives each span's free length (tangent to tangent at the solved arm angle,
    equal to the layout's own geometry there) beside the model's (between its end nodes, which the
    pulleys' turns under load slide along the span: the difference is the two ends' slides).
    Where a hybrid span's end node sits more than END_SLIDE_FRACTION of the span from its tangent
    point a warning says so, as in a transient; the rotational model, which has no transverse
    modes, gives none."""
    from beltjax.span_flags import END_SLIDE_FRACTION
    from beltjax.static_state import _length_note

    text = _tensioner(drag=0.0).replace(f"mean_Nm = {M_ALT}", "mean_Nm = 20.0")
    sc = loads_scene(text)
    r = statics.analyse_statics(sc)
    exact = np.asarray(sc.geometry(np.radians(r.tensioner_angle_deg), check=False).span_length)
    np.testing.assert_allclose(r.span_free_lengths_m, exact, rtol=1e-12)
    assert r.to_json()["span_free_lengths_m"] == pytest.approx(list(exact), rel=1e-12)
    slides = np.asarray(drive.end_slides(r.qi, sc, r.inst))
    np.testing.assert_allclose(r.span_lengths_m - r.span_free_lengths_m, slides[:, 1] - slides[:, 0], atol=1e-12)
    frac = np.max(np.abs(slides), axis=1) / r.span_free_lengths_m
    j = int(np.argmax(frac))
    assert frac[j] > END_SLIDE_FRACTION  # the alternator's load turned the pulleys this far (else no test)
    assert r.length_note is None  # rotational
    hybrid = loads_scene(text.replace('fidelity = "rotational"', 'fidelity = "ancf"'))  # same statics (tested)
    note = _length_note(hybrid, r.span_names, slides, r.span_free_lengths_m, "operating point")
    assert note.startswith(f"span {r.span_names[j]!r} of the hybrid model: its end nodes sit up to "
                           f"{1e3 * frac[j] * r.span_free_lengths_m[j]:.3g} mm ({100 * frac[j]:.3g} % of the span)")
    small = slides * 0.99 * END_SLIDE_FRACTION / frac[j]
    assert _length_note(hybrid, r.span_names, small, r.span_free_lengths_m, "operating point") is None


def test_an_arm_that_balances_the_belt_at_two_angles_is_told():
    """The thesis' tensioner bench: the spring balances the installed belt at two stable arm
    angles (an unstable one between).  The installation takes the one nearest the scene's
    arm_angle_deg and says so, naming the other; given near the other, it installs there."""
    sc = loads_scene(_tensioner())
    r = statics.analyse_statics(sc, with_unloaded=False)
    low, high = r.arm_balances_deg
    installed = math.degrees(float(r.inst.arm_angle))
    assert low == pytest.approx(installed, abs=0.01) and high == pytest.approx(117.4, abs=0.05)  # (README)
    for a in (low, high):  # each a root of the arm's balance (to the scan's interpolation)
        assert abs(float(statics._arm_residual(math.radians(a), sc))) < 1e-3 * float(r.spring_moment_Nm)
    assert r.arm_note in r.warnings and f"taken as nearest tensioner.arm_angle_deg = 46.5 deg, and {high:.4g} deg" in r.arm_note
    other = statics.analyse_statics(loads_scene(_tensioner().replace("arm_angle_deg = 46.5 ", f"arm_angle_deg = {high:.1f} ")),
                                    with_unloaded=False)
    assert math.degrees(float(other.inst.arm_angle)) == pytest.approx(high, abs=0.01)
    assert other.arm_balances_deg == pytest.approx([low, high], abs=1e-3)  # (the scan, about another guess)
    assert statics.analyse_statics(loads_scene(FEAD), with_unloaded=False).arm_note is None  # one balance
