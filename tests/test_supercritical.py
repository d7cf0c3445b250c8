"""Past the critical belt speed, flagged everywhere (issue 20, item 1; beltjax.critical).

A span's force on its pulleys is T - rhoA c^2 lam; where it reaches zero the belt would lift
off and no answer of the model is physical.  With fixed centres the elastic tension does not
depend on the speed, so the critical speed is sqrt(T lam / rhoA) exactly (40.69 m/s for the
two-pulley bench at 200 N: 3828 rpm of the crank); a tensioner raises the tension with the
speed, so there it must be found along the steady motions.

Checked: statics (a one-line error naming the span, the speed and the critical speed; no
error just below it), modal (stable: false with the reason, in both fidelities: the
rotational model's massless spans used to be reported stable at 7.8x the critical speed),
Campbell (unstable past it), sweeps (status "supercritical"), a rotational run-up through it
(recorded and warned, by the CLI), and the pure check for optimisers (its gradient).

Cheap: the bench with 4 ANCF elements per span (the sweep uses test_sweep.py's options, so
that both share one compiled batch) and the rotational model elsewhere.
"""

from __future__ import annotations

import dataclasses
import json
import math

import equinox as eqx
import jax
import numpy as np
import pytest

from beltjax import campbell, critical, drive, drive_modal, statics, sweep, transient
from beltjax.cli import main
from beltjax.scene import loads_scene

from _scenes import scene_text, substitute

T200 = scene_text("two_pulley_T200.toml")


def _hybrid_text(n=4):
    return substitute(T200, ("elements_per_span = 16", f"elements_per_span = {n}"))


def _rotational_text():
    return substitute(T200, ('fidelity = "ancf"', 'fidelity = "rotational"'))


@pytest.fixture(scope="module")
def hybrid():
    return loads_scene(_hybrid_text())


@pytest.fixture(scope="module")
def rotational():
    return loads_scene(_rotational_text())


@pytest.fixture(scope="module")
def v_crit(rotational):
    """sqrt(T lam / rhoA) (m/s) of the bench at 200 N: where T - rhoA c^2 lam vanishes."""
    lam = float(statics.install(rotational).stretch)
    return math.sqrt(200.0 * lam / float(rotational.belt.rhoA))


def _rpm(scene, v):
    return v / float(scene.pulley("crank").radius) * 60 / (2 * math.pi)


# --------------------------------------------------------------------------- statics


def test_statics_refuses_a_speed_past_the_critical_speed(hybrid, v_crit):
    """At 1.001 v_c a one-line StaticsError names a span, the speed and the critical speed
    (to 4 digits); critical_speed() brackets v_c to 1e-6; at 0.999 v_c the statics runs and
    every span force is T - rhoA v^2 / lam > 0 (to 1e-9 N)."""
    below = statics.analyse_statics(hybrid, 0.999 * v_crit)
    lam = below.stretch
    np.testing.assert_allclose(below.span_forces_N, 200.0 - float(hybrid.belt.rhoA) * (0.999 * v_crit) ** 2 / lam,
                               atol=1e-9)
    assert np.all(below.span_forces_N > 0) and below.supercritical is None
    with pytest.raises(statics.StaticsError) as err:
        statics.analyse_statics(hybrid, 1.001 * v_crit)
    msg = str(err.value)
    print(f"\n  {msg}")
    assert "\n" not in msg
    assert msg.split(":")[0] in ("crank-alternator", "alternator-crank")
    assert f"is past the critical speed {v_crit:.4g} m/s" in msg
    assert f"({_rpm(hybrid, 1.001 * v_crit):.5g} rpm of crank)" in msg
    assert critical.critical_speed(hybrid, 1.001 * v_crit) == pytest.approx(v_crit, rel=1e-6)
    assert critical.critical_speed(hybrid, 0.999 * v_crit) is None


def test_statics_command_past_the_critical_speed(tmp_path, capsys, v_crit):
    """`beltjax statics` with the crank at 30000 rpm (319 m/s, 7.8 v_c): exit 2, one line on
    stderr naming the span and the critical speed, no statics.json (no hub forces printed:
    they used to be 24 kN pointing the wrong way)."""
    path = tmp_path / "scene.toml"
    path.write_text(substitute(_hybrid_text(), ("speed_rpm = 0.0 ", "speed_rpm = 30000.0 ")))
    code = main(["statics", str(path), "--out", str(tmp_path / "out")])
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert code == 2 and len(lines) == 1, cap.err
    assert lines[0].startswith("beltjax: error: ") and "-crank: belt speed 318.9 m/s (30000 rpm of crank)" in lines[0]
    assert f"critical speed {v_crit:.4g} m/s" in lines[0]
    assert "hub" not in cap.out and not (tmp_path / "out" / "statics.json").exists()


def test_tensioner_critical_speed_follows_the_steady_motions():
    """Tensioner bench (rotational): the arm raises the tension with the speed, so the drive's
    critical speed lies above the spans' sqrt(T lam / rhoA) at rest; critical_speed() finds
    the speed where the lowest span force changes sign along the equilibria, checked
    independently at (1 -+ 1e-6) of it."""
    text = substitute(scene_text("tensioner_bench_stage2.toml"), ('fidelity = "ancf"', 'fidelity = "rotational"'))
    sc = drive.canonical(loads_scene(text))
    rest = statics.analyse_statics(sc, 0.0)
    at_rest = math.sqrt(min(rest.span_tensions_N) * rest.stretch / float(sc.belt.rhoA))
    vc = critical.critical_speed(sc, 150.0)
    print(f"\n  tensioner bench: critical speed {vc:.4f} m/s; sqrt(T lam / rhoA) at rest {at_rest:.2f} m/s")
    assert vc > 1.2 * at_rest
    for u, sign in ((vc * (1 - 1e-6), 1), (vc * (1 + 1e-6), -1)):
        out, conv, _, _ = statics.solve_at(sc, u)
        f = critical.output_forces(sc, out, u)
        assert conv and (np.all(f > 0) if sign > 0 else np.min(f) <= 0), (u, f)
    with pytest.raises(statics.StaticsError, match=f"past the critical speed {vc:.4g} m/s"):
        statics.analyse_statics(sc, 1.01 * vc)


# --------------------------------------------------------------------------- modal and Campbell


def test_modal_past_the_critical_speed_is_unstable(hybrid, rotational, v_crit):
    """Past v_c analyse_modes reports stable: false, no frequencies and the reason, in both
    fidelities; below it the rotational model has its 1st rotational mode."""
    for sc in (hybrid, rotational):
        m = drive_modal.analyse_modes(sc, 1.01 * v_crit)
        assert not m.stable and len(m.frequencies_hz) == 0
        assert "past the critical speed" in m.unstable_reason
        data = m.to_json()
        assert data["stable"] is False and data["unstable_reason"] == m.unstable_reason
    ok = drive_modal.analyse_modes(rotational, 0.99 * v_crit)
    assert ok.stable and ok.unstable_reason is None and ok.labels[1].startswith("1st rotational")


def test_modal_command_past_the_critical_speed(tmp_path, capsys, rotational, v_crit):
    """`beltjax modal --rpm` past v_c prints UNSTABLE with the reason (exit 0, modal.json)."""
    path = tmp_path / "scene.toml"
    path.write_text(_rotational_text())
    rpm = _rpm(rotational, 1.5 * v_crit)
    assert main(["modal", str(path), "--rpm", f"{rpm:.6f}", "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "UNSTABLE at belt speed" in out and "past the critical speed" in out
    data = json.loads((tmp_path / "out" / "modal.json").read_text())
    assert data["stable"] is False and "critical speed" in data["unstable_reason"]


def test_campbell_past_the_critical_speed_is_unstable(rotational, v_crit):
    """Campbell of the rotational bench: stable up to v_c, unstable (NaN) past it."""
    rpm = np.array([0.0, 0.5, 0.99, 1.01, 2.0]) * _rpm(rotational, v_crit)
    c = campbell.analyse_campbell(rotational, rpm, n_modes=2)
    assert list(c.stable) == [True, True, True, False, False]
    assert np.all(np.isfinite(c.frequencies_hz[:3, 1])) and np.all(np.isnan(c.frequencies_hz[3:]))


# --------------------------------------------------------------------------- sweeps and the pure check


def test_sweep_case_past_the_critical_speed_has_a_status(hybrid, v_crit):
    """A sweep of the crank's speed_rpm: cases below v_c are "ok", those past it
    "supercritical" with NaN outputs (the options of test_sweep.py: one compiled batch)."""
    sc = eqx.tree_at(lambda s: s.model, hybrid, dataclasses.replace(hybrid.model, elements_per_span=4))
    crit = _rpm(sc, v_crit)
    spec = sweep.parse_spec({"outputs": ["statics", "modal"], "modes": 8, "grid": [
        {"parameter": "pulley.crank.speed_rpm", "values": [0.0, 0.9 * crit, 1.01 * crit, 30000.0]}]})
    res = sweep.evaluate(sc, sweep.cases(sc, spec), ("statics", "modal"), 8, chunk=8)
    assert list(res["status"]) == ["ok", "ok", "supercritical", "supercritical"]
    assert np.all(np.isnan(res["span_tensions_N"][2:])) and np.all(np.isfinite(res["span_tensions_N"][:2]))
    assert "supercritical" in sweep.failures(res) and sweep.REASONS["supercritical"].startswith("past the critical")


def test_pure_check_is_differentiable(rotational):
    """critical.span_forces through the statics' implicit derivatives (what an optimiser
    calls).  With fixed centres F = T - rhoA v^2 / lam, lam the installation stretch (the
    spans keep it): dF/dT = 1 + rhoA v^2 / lam^2 / (dT/dlam), dT/dlam = EA (3 lam^2 - 1) / 2,
    and dF/d rhoA = -v^2 / lam (1e-6)."""
    v = 30.0

    def forces(T, rhoA):
        b = dataclasses.replace(rotational.belt, static_tension=T, rhoA=rhoA)
        sc = eqx.tree_at(lambda s: s.belt, rotational, b)
        qi, inst, _ = statics.equilibrium(sc, speed=v)
        return critical.span_forces(sc, qi, inst, v)

    T, rhoA = rotational.belt.static_tension, rotational.belt.rhoA
    dT, drho = jax.jit(jax.jacfwd(forces, argnums=(0, 1)))(T, rhoA)
    lam = float(statics.install(rotational).stretch)
    dT_dlam = float(rotational.belt.EA) * (3 * lam**2 - 1) / 2
    np.testing.assert_allclose(np.asarray(dT), 1 + float(rhoA) * v**2 / lam**2 / dT_dlam, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(drho), -(v**2) / lam, rtol=1e-6)
    for speed, past in ((50.0, True), (v, False)):
        out, conv, _, _ = statics.solve_at(drive.canonical(rotational), speed)
        assert conv and bool(critical.supercritical(rotational, out["qi"], out["inst"], speed)) is past


# --------------------------------------------------------------------------- transients


def test_runup_through_the_critical_speed_is_recorded_and_warned(tmp_path, capsys, v_crit):
    """Rotational bench driven from 3700 rpm at 500 rpm/s for 0.5 s (v_c at 3828 rpm, 0.26 s):
    `beltjax simulate` prints one warning line per span and simulation.json records each span
    past the critical speed (first and last times, lowest force, belt speed at the first
    sample), consistent with the span_forces_N channel; the run is not refused.  The
    alternator's acceleration splits the spans' forces (J alpha / R, +-3 N, and as much
    ringing: 0.1 s either side of the crossing at 5.3 m/s^2), not their mean, which crosses
    zero at the critical speed (within 2 output samples)."""
    text = substitute(_rotational_text(), ("driven = false ", "driven = true "),
                      ("speed_rpm = 0.0 ", "speed_rpm = 3700.0\nacceleration_rpm_per_s = 500.0 "))
    text += '\n[simulation]\nsolver = "generalized_alpha"\ndt_s = 2e-4\noutput_dt_s = 1e-3\n'
    path = tmp_path / "runup.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["simulate", str(path), "--t-end", "0.5", "--out", str(out)]) == 0
    stdout = capsys.readouterr().out
    warned = [line for line in stdout.splitlines() if "passed the critical speed" in line]
    assert len(warned) == 2 and all(line.startswith("warning: span ") for line in warned)
    meta = json.loads((out / "simulation.json").read_text())["meta"]
    recs = {r["span"]: r for r in meta["supercritical_spans"]}
    assert set(recs) == {"crank-alternator", "alternator-crank"} and meta["slack_spans"] == []
    data = np.load(out / "simulation.npz")
    t, F, v = data["t_s"], data["span_forces_N"], data["belt_speed_m_s"]
    t_cross = (_rpm(loads_scene(text), v_crit) - 3700.0) / 500.0
    for j, name in enumerate(data["span_forces_N__columns"]):
        r = recs[str(name)]
        bad = F[:, j] <= 0
        assert r["samples"] == bad.sum() and r["t_last_s"] == pytest.approx(0.5)
        k = int(np.argmax(bad))
        assert r["t_first_s"] == pytest.approx(t[k]) and F[k - 1, j] > 0
        assert r["min_force_N"] == pytest.approx(F[:, j].min()) and r["belt_speed_m_s"] == pytest.approx(v[k])
        print(f"\n  {name}: past the critical speed from t = {r['t_first_s']:.3f} s (v = {r['belt_speed_m_s']:.2f} m/s;"
              f" critical speed {v_crit:.2f} m/s at {t_cross:.3f} s), force down to {r['min_force_N']:.1f} N")
    first = sorted(r["t_first_s"] for r in recs.values())
    t_mean = t[int(np.argmax(F.mean(axis=1) <= 0))]
    assert first[0] <= t_mean <= first[1] and abs(t_mean - t_cross) <= 2e-3


def test_span_flags_share_one_mechanism():
    """slack_spans and supercritical_spans are one episode finder; run_warnings words both."""
    t = np.linspace(0, 1, 11)
    F = np.stack([np.linspace(5, -5, 11), np.full(11, 3.0)], axis=1)
    rec = transient.supercritical_spans(t, F, ["a-b", "b-a"], np.linspace(10, 20, 11))
    assert rec == [dict(span="a-b", t_first_s=0.5, t_last_s=1.0, samples=6, min_force_N=-5.0, belt_speed_m_s=15.0)]
    slack = transient.slack_spans(t, F, ["a-b", "b-a"])
    assert [(r["span"], r["t_first_s"], r["samples"]) for r in slack] == [("a-b", 0.5, 6)]
    lines = transient.run_warnings(dict(slack_spans=slack, supercritical_spans=rec))
    assert len(lines) == 2 and "went slack" in lines[0] and "passed the critical speed" in lines[1]


def test_a_slack_span_is_not_also_past_the_critical_speed():
    """A span whose tension is <= 0 is slack (its force on the pulleys is then <= 0 too, at any
    speed): it is flagged once, as slack, not also as past the critical speed from belt speed 0."""
    t = np.linspace(0, 1, 11)
    T = np.stack([np.linspace(5, -5, 11), np.full(11, 3.0)], axis=1)
    F = T - np.stack([np.zeros(11), np.linspace(0, 6, 11)], axis=1)  # the second: past critical late on
    rec = transient.supercritical_spans(t, F, ["a-b", "b-a"], np.zeros(11), T)
    assert [(r["span"], r["t_first_s"], r["samples"]) for r in rec] == [("b-a", 0.5, 6)]
    assert [r["span"] for r in transient.slack_spans(t, T, ["a-b", "b-a"])] == ["a-b"]


def test_the_slip_warning_says_whether_the_belt_slid():
    from beltjax.span_flags import slip_warning

    rec = dict(pulley="crank", samples=3, t_first_s=0.1, t_last_s=0.2, min_slip_margin=-0.5)
    assert "does not slip" in slip_warning(rec) and "list belt_slip" in slip_warning(rec)
    assert "slid on 'crank'" in slip_warning(dict(rec, slides=True))


def test_a_span_stretched_beyond_the_belt_law_is_flagged():
    """A span whose strain T / EA passes MAX_RUN_STRAIN during a run is flagged with its largest
    strain and worded by run_warnings (a fuzzed run-up reached a strain of 1700, flagged only as
    slack on the other span)."""
    from beltjax.span_flags import MAX_RUN_STRAIN, overstretched_spans

    t = np.linspace(0, 1, 11)
    EA = 1e5
    T = np.stack([np.linspace(0, 2 * MAX_RUN_STRAIN * EA, 11), np.full(11, 500.0)], axis=1)
    rec = overstretched_spans(t, T, EA, ["a-b", "b-a"])
    assert [(r["span"], r["t_first_s"], r["samples"]) for r in rec] == [("a-b", 0.5, 6)]
    assert rec[0]["max_strain"] == pytest.approx(2 * MAX_RUN_STRAIN)
    (line,) = transient.run_warnings(dict(overstretched_spans=rec))
    assert "stretched by up to 10 %" in line
