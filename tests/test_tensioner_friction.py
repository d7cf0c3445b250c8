"""The tensioner's pivot: dry friction (regularised Coulomb, optionally asymmetric) and end stops
(beltjax.drive.pivot), checked against Den Hartog's exact Coulomb oscillator, the energy per
cycle, the torque-angle fit it is pasted from, and in scenes and transients."""

from __future__ import annotations

import math
import re
import pathlib
import types

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import statics
from beltjax.drive import effects_of, pivot
from beltjax.errors import BeltjaxError
from beltjax.scene import loads_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _pivot(Tf, a=1.0, w_r=1e-3, k=1.0, theta0_deg=0.0, stops=(None, None), ks=1e4, tau=1e-4):
    return types.SimpleNamespace(friction_moment=Tf, friction_asymmetry=a, friction_speed=w_r, spring_stiffness=k,
                                 spring_preload_deg=theta0_deg, stop_min_deg=stops[0], stop_max_deg=stops[1],
                                 stop_stiffness=ks, friction_stick_time=tau)


@jax.jit
def _solve(p):
    """The forced Coulomb oscillator with the pivot's friction law over six periods from state
    y0; p = (P, F, k, m, w, w_r, tau, phi, X0): one compilation for every case."""
    P, F, k, m, w, w_r, tau, phi, X0 = p
    f = pivot.coulomb_oscillator(P, k, m, w, phi, _pivot(F, w_r=w_r, tau=tau))
    T = 2 * jnp.pi / w
    ts = 6 * T * jnp.linspace(5.0 / 6.0, 1.0, 2001)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(f), diffrax.Dopri8(), 0.0, 6 * T, T / 200,
                              jnp.stack([X0, 0.0, 0.0]), saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12), max_steps=200000)
    return sol.ys


def _oscillate(P, F, k, m, w, w_r, tau, X0=None):
    """The oscillator from Den Hartog's periodic state (or from rest at X0): (exact amplitude, the
    last period's amplitude, its friction work (J), its mean position)."""
    X_dh, phi = pivot.den_hartog(P, F, k, m, w) if X0 is None else (None, 0.0)
    ys = np.asarray(_solve(jnp.array([P, F, k, m, w, w_r, tau, phi, X_dh if X0 is None else X0])))
    x, e = ys[:, 0], ys[:, 2]
    return X_dh, 0.5 * (x.max() - x.min()), e[-1] - e[0], x.mean()


@pytest.mark.parametrize("r, ratio", [(0.8, 0.2), (1.6, 0.3)])
def test_den_hartog_amplitude_and_energy_per_cycle(r, ratio):
    """The regularised law (omega_r a thousandth of the peak speed, tau a ten-thousandth of the
    period) gives Den Hartog's exact steady amplitude to 0.2 %, and the energy dissipated per
    cycle is 4 F X0 to 0.2 %."""
    k, m, P = 1.0, 1.0, 1.0
    w = r * math.sqrt(k / m)
    X0 = pivot.den_hartog(P, ratio * P, k, m, w)[0]
    exact, amp, work, _ = _oscillate(P, ratio * P, k, m, w, w_r=1e-3 * w * X0, tau=1e-4 * 2 * math.pi / w)
    assert amp == pytest.approx(exact, rel=2e-3)
    assert work == pytest.approx(4 * ratio * P * amp, rel=2e-3)


@pytest.mark.parametrize("which", ["w_r", "tau"])
def test_regularisation_error_shrinks(which):
    """The amplitude error of the regularisation falls as omega_r and as tau do (measured, not
    assumed).  Measured here, the error is about the lesser of 0.38 omega_r / (w X0) and
    2.7 tau / T: the reversal is Coulomb's if either is small, so each is varied with the other
    large (a tenth of the peak speed, of the period)."""
    k, m, P, F, w = 1.0, 1.0, 1.0, 0.3, 1.6
    X0 = pivot.den_hartog(P, F, k, m, w)[0]
    T = 2 * math.pi / w
    errs = []
    for q in ((1e-1, 1e-2) if which == "w_r" else (1e-2, 1e-3)):
        w_r, tau = (q * w * X0, 1e-1 * T) if which == "w_r" else (1e-1 * w * X0, q * T)
        errs.append(abs(_oscillate(P, F, k, m, w, w_r=w_r, tau=tau)[1] / X0 - 1))
    assert errs[1] < 0.3 * errs[0]


def test_a_held_oscillator_does_not_creep():
    """A friction band above the force's amplitude holds the mass where it starts: it stays
    there (the regularised tanh law this replaced let it creep at a speed set by omega_r)."""
    k, m, P, F, w = 1.0, 1.0, 1.0, 1.5, 1.6
    _, amp, work, mean = _oscillate(P, F, k, m, w, w_r=1e-2, tau=1e-2, X0=0.2)
    assert amp < 1e-6 and abs(mean - 0.2) < 1e-6  # the spring's 0.2 N is inside the band too
    assert abs(work) < 1e-9


def test_asymmetric_band():
    """Loading (moving away from the free angle) takes a times the unloading moment; the mean is T_f."""
    t = _pivot(2.0, a=3.0, w_r=1e-6, theta0_deg=0.0)
    load = float(-pivot.friction_moment(1.0, 0.5, 0.0, 1.0, t))     # theta > theta_0, moving away
    unload = float(pivot.friction_moment(-1.0, 0.5, 0.0, 1.0, t))   # moving back towards it
    assert load / unload == pytest.approx(3.0, rel=1e-9)
    assert 0.5 * (load + unload) == pytest.approx(2.0, rel=1e-9)
    # the same below the free angle, mirrored
    assert float(pivot.friction_moment(-1.0, -0.5, 0.0, 1.0, t)) == pytest.approx(load, rel=1e-9)
    # finite derivatives at rest and with no friction (the band's closing and edges are smooth there)
    for Tf in (0.0, 2.0):
        g = jax.grad(lambda w, T: pivot.friction_moment(w, 0.5, 3.0, 1.0, _pivot(T, a=3.0, w_r=1e-2)),
                     argnums=(0, 1))(0.0, Tf)
        assert all(np.isfinite(float(x)) for x in g)


def test_stops_are_conservative_and_only_outside():
    t = _pivot(0.0, k=20.0, theta0_deg=40.0, stops=(50.0, 85.0), ks=1e4)
    th = jnp.deg2rad(jnp.array([60.0, 70.0, 84.9]))
    assert np.allclose(pivot.stop_moment(th, t), 0.0)
    assert float(pivot.stop_moment(jnp.deg2rad(86.0), t)) == pytest.approx(-1e4 * math.radians(1.0))
    assert float(pivot.stop_moment(jnp.deg2rad(49.0), t)) == pytest.approx(1e4 * math.radians(1.0))
    # a potential: the moment is minus the derivative of its integral (path independence, C1)
    g = jax.grad(lambda x: pivot.stop_moment(x, t))(jnp.deg2rad(86.0))
    assert float(g) == pytest.approx(-1e4)


def test_pasted_fit_block_reproduces_the_torque_angle_loop():
    """A slow arm cycle of the scene with the fit's [tensioner] block pasted in gives the fitted
    loop: the pivot moments (spring + friction, the spring's sense) equal the fit's branches away
    from the turning points."""
    from identification import torque_angle

    ds = ROOT / "identification" / "examples" / "tensioner_torque_angle" / "dataset.toml"
    import tomllib

    sec = tomllib.loads(ds.read_text())["torque_angle"]
    sec.pop("friction", None)
    res = torque_angle.fit_torque_angle(sec, ds.parent, "torque_angle")
    block = res.scene_block()
    text = (ROOT / "scenes" / "tensioner_bench_stage2.toml").read_text()
    lines = [ln for ln in block.splitlines() if "=" in ln and not ln.startswith("#")]
    for ln in lines:  # the fitted keys replace the scene's
        text = re.sub(rf"^{ln.split('=')[0].strip()}\s*=.*$", "", text, flags=re.M)
    text = re.sub(r"^\[tensioner\]", lambda _: "[tensioner]\n" + "\n".join(lines), text, count=1, flags=re.M)
    text = re.sub(r"^effects\s*=\s*\[", 'effects = ["tensioner_friction", ', text, count=1, flags=re.M)
    scene = loads_scene(text)
    assert "tensioner_friction" in effects_of(scene)
    t = scene.tensioner
    assert float(t.friction_moment) == pytest.approx(res.friction_band_Nm, rel=1e-5)
    lo, hi = res.angle_range_deg
    ts = np.linspace(0.0, 10.0, 2001)  # one 0.1 Hz cycle over the fitted range
    theta = np.deg2rad(0.5 * (lo + hi) + 0.4 * (hi - lo) * np.sin(2 * np.pi * 0.1 * ts))
    omega = np.gradient(theta, ts)
    # a prescribed motion: the arm slides, so the moment is the band's edge whatever holds it
    model = np.asarray(pivot.elastic_moment(jnp.asarray(theta), t) + pivot.friction_moment(
        jnp.asarray(omega), jnp.asarray(theta), 0.0, 1.0, t))
    sliding = np.abs(omega) > 5 * float(t.friction_speed)
    fitted = res.predict(np.rad2deg(theta), np.sign(omega))
    assert np.max(np.abs(model - fitted)[sliding]) < 1e-3 * np.ptp(fitted)


def _fead(extra_tensioner: str = "", effect: bool = True) -> str:
    text = (ROOT / "scenes" / "fead_8pulley.toml").read_text()
    text = text.replace("damping = 0.5 ", extra_tensioner + "\ndamping = 0.5 ", 1)
    if effect:
        text = text.replace('effects = ["transport"', 'effects = ["tensioner_friction", "transport"', 1)
    return text


@pytest.mark.parametrize("extra, key", [
    ("friction_moment = -1.0", "tensioner.friction_moment"),
    ("stop_min_deg = 85.0\nstop_stiffness = 0.0", "tensioner.stop_stiffness"),
    ("stop_min_deg = 60.0\nstop_max_deg = 50.0", "tensioner.stop_max_deg"),
    ("friction_speed = 0.0", "tensioner.friction_speed"),
    ("friction_stick_time = -1e-4", "tensioner.friction_stick_time"),
])
def test_bad_pivot_inputs_name_the_key(extra, key):
    with pytest.raises(BeltjaxError) as e:
        loads_scene(_fead(extra))
    assert key in str(e.value)
    assert "\n" not in str(e.value)


def test_friction_without_its_effect_is_refused():
    with pytest.raises(BeltjaxError, match="tensioner_friction"):
        loads_scene(_fead("friction_moment = 1.0", effect=False))


def test_stops_enter_the_installation():
    """A stop inside the spring's travel holds the arm there: the installed arm angle moves to
    the stop (within the stop's compliance), and the belt's tension follows."""
    free = statics.install(loads_scene(_fead(effect=False)))
    a = math.degrees(float(free.arm_angle))
    stopped = statics.install(loads_scene(_fead(f"stop_max_deg = {a - 5.0}\narm_angle_deg = {a - 6.0}",
                                                effect=False).replace("arm_angle_deg = 80.0", "")))
    assert math.degrees(float(stopped.arm_angle)) == pytest.approx(a - 5.0, abs=0.5)


def test_stops_are_checked_against_the_settled_arm_not_the_first_guess():
    """arm_angle_deg is the statics' first guess: stops 0.3 deg either side of the arm's settled
    angle, far from the guess (80 deg), are accepted, and the arm settles between them."""
    free = statics.install(loads_scene(_fead(effect=False)))
    a = math.degrees(float(free.arm_angle))
    assert abs(a - 80.0) > 5.0
    inst = statics.install(loads_scene(_fead(f"stop_min_deg = {a - 0.3}\nstop_max_deg = {a + 0.3}", effect=False)))
    assert math.degrees(float(inst.arm_angle)) == pytest.approx(a, abs=1e-6)


def test_an_operating_point_pressed_into_a_stop_is_reported():
    """Stops that hold the installed arm between them but not the loaded one: the operating point
    reports the arm resting on its stop (a warning line and statics.json's arm_on_stop)."""
    from beltjax.static_state import analyse_statics

    plain = analyse_statics(loads_scene(_fead(effect=False)))
    a_op, a_in = plain.tensioner_angle_deg, plain.unloaded["tensioner_angle_deg"]
    assert abs(a_op - a_in) > 0.5 and plain.arm_on_stop is None
    lo, hi = (0.5 * (a_op + a_in), a_in + 5.0) if a_op < a_in else (a_in - 5.0, 0.5 * (a_op + a_in))
    r = analyse_statics(loads_scene(_fead(f"stop_min_deg = {lo}\nstop_max_deg = {hi}", effect=False)))
    key = "stop_min_deg" if a_op < a_in else "stop_max_deg"
    assert r.arm_on_stop and f"tensioner.{key}" in r.arm_on_stop and r.to_json()["arm_on_stop"] == r.arm_on_stop
    assert r.arm_on_stop in r.warnings


def test_a_stop_that_holds_the_installed_arm_is_refused():
    """Stops must contain the installed arm: one that the arm settles on is an error naming it
    (checked on the settled arm, not on arm_angle_deg, the statics' first guess)."""
    from beltjax.static_state import analyse_statics

    free = statics.install(loads_scene(_fead(effect=False)))
    a = math.degrees(float(free.arm_angle))
    text = _fead(f"stop_max_deg = {a - 5.0}", effect=False).replace("arm_angle_deg = 80.0", f"arm_angle_deg = {a - 6}")
    with pytest.raises(statics.StaticsError) as e:
        analyse_statics(loads_scene(text), loaded=False)
    assert e.value.key == "tensioner.stop_max_deg"


def _bench_with_friction(fidelity: str, effects: str = ""):
    import dataclasses

    from beltjax import drive

    sc = loads_scene((ROOT / "scenes" / "tensioner_bench_stage2.toml").read_text().replace(
        'effects = [', 'effects = ["tensioner_friction", ' + effects, 1).replace(
        "[tensioner]", "[tensioner]\nfriction_moment = 1.0\nfriction_asymmetry = 3.0\nfriction_stick_time = 1e-3", 1
    ).replace('fidelity = "ancf"', f'fidelity = "{fidelity}"', 1).replace(
        "[belt]", "[belt]\nfriction_coefficient = 0.5" if "belt_slip" in effects else "[belt]", 1))
    return drive.canonical(dataclasses.replace(sc, model=dataclasses.replace(sc.model, fidelity=fidelity,
                                                                             elements_per_span=1)))


@pytest.mark.parametrize("fidelity", ["rotational", "ancf"])
def test_drive_friction_holds_or_slides_with_the_band(fidelity):
    """In the drive's equations (both fidelities' structured solves), the friction is one moment
    at the arm: M_ii q_i'' - F_ii (the dense equations without it) is zero but for the arm's row,
    and that row is the switch law on the dense equations' own numbers: the moment that makes the
    arm's acceleration -omega / tau, -(theta''_0 + omega / tau) J_eff with theta''_0 and 1 / J_eff
    the arm's entries of M_ii^-1 F_ii and M_ii^-1 e_arm, held inside the band.  At rest the band
    is [-(T_f + D s), T_f - D s] (a wide band holds the arm: its acceleration is -omega / tau,
    it does not creep; a narrow one breaks away at its edge); sliding far faster than omega_r it
    is the sliding edge, -(T_f + D s) or T_f - D s."""
    import dataclasses

    from beltjax import drive

    sc = _bench_with_friction(fidelity)
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    arm = drive.n_rigid(sc) - 1
    rng = np.random.default_rng(3)
    qi = drive.installed_coordinates(sc, inst) + 1e-4 * jnp.asarray(rng.standard_normal(n))
    rm = drive.reduced_mass(sc, inst)
    t = sc.tensioner
    s = math.copysign(1.0, float(inst.arm_angle + qi[arm]) - math.radians(float(t.spring_preload_deg)))

    @jax.jit
    def run(qd, Tf):
        sT = dataclasses.replace(sc, tensioner=dataclasses.replace(sc.tensioner, friction_moment=Tf))
        a = drive.reduced_accelerations(qi, qd, sT, inst, rm, t=0.01)
        M, F = drive.reduced_system(qi, qd, sT, inst, t=0.01)
        a0 = jnp.linalg.solve(M, F)[arm]
        c = jnp.linalg.solve(M, jnp.zeros(n).at[arm].set(1.0))[arm]
        return a, M @ a - F, jnp.max(jnp.abs(F)), -(a0 + qd[arm] / 1e-3) / c

    held = 0
    for w_arm, Tf in ((1e-4, 50.0), (0.0, 50.0), (0.0, 1e-3), (3.0, 1.0), (-3.0, 1.0)):
        qd = jnp.zeros(n).at[arm].set(w_arm)
        a, r, scale, needed = run(qd, Tf)
        assert np.max(np.abs(np.delete(np.asarray(r), arm))) < 1e-9 * float(scale)
        m = float(r[arm])  # the friction moment the drive applied (N m)
        up, down = Tf * (1 + 0.5 * s), Tf * (1 - 0.5 * s)  # D = T_f (a - 1) / (a + 1) = T_f / 2 at a = 3
        lo, hi = (-up, down) if w_arm == 0 or abs(w_arm) < 1e-3 else ((-up, -up) if w_arm > 0 else (down, down))
        assert m == pytest.approx(float(np.clip(float(needed), lo, hi)), rel=1e-6, abs=1e-9 * Tf)
        if lo < float(needed) < hi:  # held: the arm comes to rest
            held += 1
            assert float(a[arm]) == pytest.approx(-w_arm / 1e-3, abs=1e-9 * float(scale))
    assert held == 2  # the wide band held the arm; the narrow one (1e-3 N m) let it break away


def test_drive_friction_with_slip_states():
    """With belt_slip's states (the accelerations returned beside the slip rates): the friction
    leaves the slip rates alone and acts on the arm's row as without them (T_f = 0: the drive
    without the effect)."""
    import dataclasses

    from beltjax import drive
    from beltjax.drive import belt_slip

    sc = _bench_with_friction("rotational", '"belt_slip", ')
    bare = _bench_with_friction("rotational", '"belt_slip", ')
    bare = dataclasses.replace(bare, model=dataclasses.replace(bare.model, effects=tuple(
        e for e in bare.model.effects if e != "tensioner_friction")))
    bare = dataclasses.replace(bare, tensioner=dataclasses.replace(bare.tensioner, friction_moment=0.0))
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    arm = drive.n_rigid(sc) - 1
    rng = np.random.default_rng(4)
    qi = drive.installed_coordinates(sc, inst) + 1e-4 * jnp.asarray(rng.standard_normal(n))
    z = 1e-5 * jnp.asarray(rng.standard_normal(belt_slip.n_states(sc)))
    rm = drive.reduced_mass(sc, inst)
    qd = jnp.zeros(n).at[arm].set(2e-4)
    go = jax.jit(lambda s: drive.reduced_accelerations(qi, qd, s, inst, rm, t=0.01, slip=z))
    (a_b, z_b), (a_0, z_0) = go(bare), go(dataclasses.replace(sc, tensioner=dataclasses.replace(
        sc.tensioner, friction_moment=0.0)))
    (a_h, z_h) = go(dataclasses.replace(sc, tensioner=dataclasses.replace(sc.tensioner, friction_moment=50.0)))
    np.testing.assert_allclose(a_0, a_b, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(a_b))))
    np.testing.assert_allclose(z_0, z_b, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(z_h, z_b, rtol=1e-12, atol=1e-15)
    assert float(a_h[arm]) == pytest.approx(-2e-4 / 1e-3, rel=1e-6)  # held


@pytest.mark.parametrize("fidelity", ["rotational", "ancf"])
def test_outputs_report_the_pivot_friction(fidelity):
    """The transient's outputs report the friction moment the equations applied (from the
    constraint residual J^T R = -g M_f) and its heat -M_f omega: equal to the moment of the
    dense equations' residual, the band's sliding edge here."""
    from beltjax import drive
    from beltjax.transient_outputs import _outputs_one

    sc = _bench_with_friction(fidelity)
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    arm = drive.n_rigid(sc) - 1
    qi = drive.installed_coordinates(sc, inst)
    qd = jnp.zeros(n).at[arm].set(-3.0)  # sliding back: the moment is T_f - D s
    rm = drive.reduced_mass(sc, inst)

    @jax.jit
    def both(y):
        out = _outputs_one(0.01, y, sc, inst, drive.full_mass_matrix(sc, inst))
        a = drive.reduced_accelerations(qi, qd, sc, inst, rm, t=0.01)
        M, F = drive.reduced_system(qi, qd, sc, inst, t=0.01)
        return out["pivot_friction_moment_Nm"], out["pivot_friction_power_W"], (M @ a - F)[arm]

    m_out, p_out, m_eq = both(jnp.concatenate([qi, qd]))
    s = math.copysign(1.0, float(inst.arm_angle) - math.radians(float(sc.tensioner.spring_preload_deg)))
    assert float(m_out) == pytest.approx(float(m_eq), rel=1e-8)
    assert float(m_out) == pytest.approx(1.0 - 0.5 * s, rel=1e-6)
    assert float(p_out) == pytest.approx(3.0 * float(m_out), rel=1e-12)
