"""Responses over engine speed (beltjax.orders): the periodic steady state at each speed, batched
with vmap (equal to one-by-one runs and to a plain transient), its order content, its gradient
against finite differences, the command and its bad inputs."""

from __future__ import annotations

import json
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import cli, orders, parameters, transient
from beltjax.scene import loads_scene
from tests._scenes import scene_text

SPEEDS = [500.0, 600.0, 700.0]


def _small(tables: str = "", load: float = 5.0) -> str:
    """The thesis' tensioner bench (crank, tensioner, alternator; rotational) with a constant
    alternator load and the given [[fluctuation]] tables instead of its own excitation."""
    t = scene_text("sim_tensioner_fluctuation_load.toml")
    t = re.sub(r"fluctuation_amplitude_deg.*\n|fluctuation_frequency_hz.*\n", "", t)
    t = re.sub(r"\[\[torque\]\][^\[]*", "", t)
    t = re.sub(r"\[simulation\][^\[]*", "", t)
    return t + f'\n[[torque]]\npulley = "alternator"\nmean_Nm = {load}\n' + tables


def _order(n, amp):
    return f'[[fluctuation]]\npulley = "crank"\norder = {n}\namplitude_deg = {amp}\n'


SCENE = _small(_order(2.0, 0.5))


@pytest.fixture(scope="module")
def batched():
    return orders.response_over_speed(loads_scene(SCENE), SPEEDS, settle_s=1.0)  # one by one, a CPU's default


def test_batched_equals_one_by_one(batched):
    """One vmapped batch of the three speeds gives what each speed gives alone (the fixture: one at
    a time, a CPU's default for the shooting): adaptive steps and Newton iterations per case, not
    the batch's lock-step (a case that has converged idles while the others iterate on).  Not to
    the last bit: a vmapped kernel rounds differently, so an
    adaptive step can be accepted in one run and rejected in the other (at 600 rpm 607 steps one by
    one and 604 batched with jax 0.10.2); two step sequences of one solution agree to the
    integration's tolerance, here 10x its rtol (1e-7) of each statistic (seen: 1.04e-7)."""
    together = orders.response_over_speed(loads_scene(SCENE), SPEEDS, settle_s=1.0, chunk=3)
    assert batched.status == together.status == ["ok"] * 3
    assert batched.meta["shooting_iterations"] == together.meta["shooting_iterations"]
    for a, b in zip(batched.meta["shooting_cycle_steps"], together.meta["shooting_cycle_steps"]):
        assert np.all(np.abs(np.subtract(a, b)) <= 0.02 * np.asarray(a)), (a, b)  # each case's own cycles
    assert np.all(np.abs(np.subtract(batched.meta["steps"], together.meta["steps"])) <= 0.02 * np.asarray(batched.meta["steps"]))
    tol = 10.0 * batched.meta["rtol"]
    for k, v in batched.stats.items():
        for i, rpm in enumerate(SPEEDS):
            a, b = np.asarray(v)[i], np.asarray(together.stats[k])[i]
            assert np.max(np.abs(a - b)) <= tol * max(np.max(np.abs(a)), 1e-12), (rpm, k)


def test_steady_state_is_the_transient_and_periodic(batched):
    """At 600 rpm the settling method's recorded cycle is the plain transient (beltjax simulate) at
    the same times; the cycle found by shooting (the default, the fixture's) attracts (its largest
    Floquet multiplier below 1) and is where that transient goes: it differs from the transient's
    last cycle by less than the transient still changed between its two recorded cycles (the
    remaining start-up decays: module docstring of beltjax.orders.steady).  A second-order
    excitation gives a response of half a revolution: odd orders vanish."""
    sc = loads_scene(SCENE)
    rpm, K = 600.0, orders.Settings().samples
    period = 60.0 / rpm
    settle = orders.response_over_speed(sc, [rpm], settle_s=1.0, settings=orders.Settings(method="settle"))
    assert settle.meta["methods"] == ["settle 1 s"] and settle.meta["floquet_multipliers"] == [None]
    t_end = float(settle.meta["t_end_s"][0])
    res = transient.simulate(sc, t_end, output_dt=period / K)
    t_rec = settle.stats["t_s"][0]
    idx = np.rint(t_rec / (period / K)).astype(int)
    assert np.allclose(res.t[idx], t_rec, rtol=0, atol=1e-9)
    arm = res.channels["arm_angle_deg"][idx]
    assert np.max(np.abs(arm.max() - settle.channel("arm_angle_deg", "max")[0])) < 1e-5
    assert abs((arm.max() - arm.min()) - settle.channel("arm_angle_deg", "p2p")[0]) < 1e-5
    # shooting: the same cycle, without the start-up
    assert batched.meta["methods"] == ["shooting"] * len(SPEEDS)
    assert all(0.0 < m < 1.0 for m in batched.meta["floquet_multipliers"])
    i = SPEEDS.index(rpm)
    assert np.allclose(batched.stats["t_s"][i], t_rec - t_rec[0], rtol=0, atol=1e-9)  # the same crank phases
    early = idx - (len(res.t) - 1) // 2 // K * K  # a whole number of cycles before

    def cycle(j):  # the arm's extremes (deg) and the hub forces over the cycle (N)
        a = res.channels["arm_angle_deg"][j]
        return np.array([a.max(), a.min()]), res.channels["hub_forces_N"][j]

    (arm_late, hub_late), (arm_early, hub_early) = cycle(idx), cycle(early)
    arm_shot = np.array([batched.channel("arm_angle_deg", s)[i] for s in ("max", "min")])
    still = np.max(np.abs(arm_late - arm_early))
    assert np.max(np.abs(arm_shot - arm_late)) < still + 1e-6, (arm_shot - arm_late, still)
    still = np.max(np.abs(hub_late - hub_early))
    assert np.max(np.abs(batched.stats["hub_forces_N"][i] - hub_late)) < still + 1e-6, still
    amp = batched.channel("arm_angle_deg", "orders")  # (speeds, orders 1..8)
    assert batched.orders[:4] == [1.0, 2.0, 3.0, 4.0]
    assert np.all(amp[:, 1] > 0.1)  # the 2nd order drives the arm by tenths of a degree
    assert np.all(amp[:, [0, 2, 4, 6]] < 1e-4 * amp[:, [1]])
    assert np.all(batched.settling < 1e-6)


def test_mean_is_the_operating_point_and_small_excitation_is_linear(batched):
    """Without excitation the steady state is the operating point (no motion); a small excitation
    gives an order-2 response proportional to it.  (Through the batch the fixture compiled.)"""
    from beltjax import statics

    def of(amp):
        return orders.response_over_speed(loads_scene(_small(_order(2.0, amp))), [600.0], settle_s=1.0, chunk=3)

    out = of(0.0)
    st = statics.analyse_statics(loads_scene(_small(_order(2.0, 0.0))))
    assert abs(float(out.channel("arm_angle_deg", "mean")[0]) - st.tensioner_angle_deg) < 1e-8
    assert float(out.channel("arm_angle_deg", "p2p")[0]) < 1e-8
    a, b = of(0.01), of(0.02)
    # started on the linearised drive's periodic response, a small excitation is periodic from the start:
    # settling 1.1e-6 (from the operating point at rest it is 2.7e-3 after the same 1 s)
    assert a.settling[0] < 1e-5
    ra = float(a.channel("arm_angle_deg", "orders")[0, 1])
    assert ra > 0
    assert abs(float(b.channel("arm_angle_deg", "orders")[0, 1]) / ra - 2.0) < 2e-3


def test_linear_start_is_the_periodic_response_of_a_linear_system():
    """linear_periodic_start on a damped oscillator under two harmonics (1st and 3rd of the
    cycle; the 1st near resonance) gives the exact periodic state at t = 0 to 1e-12, and the
    damped oscillator integrated one cycle from it comes back to it."""
    from beltjax.orders.linear_start import linear_periodic_start

    wn, zeta, period = 2 * np.pi * 9.5, 0.02, 0.1
    W = 2 * np.pi / period

    def f(t, y, args):
        x, v = y[0] - 0.3, y[1]  # about the static offset 0.3 m
        a = -wn**2 * x - 2 * zeta * wn * v + 5.0 * jnp.cos(W * t + 0.4) + 2.0 * jnp.sin(3 * W * t)
        return jnp.stack([v, a])

    y = np.asarray(jax.jit(lambda y0: linear_periodic_start(f, y0, period, 64))(jnp.array([0.3, 0.0])))
    exact = np.array([0.3, 0.0], dtype=complex)
    for k, F in ((1, 5.0 * np.exp(0.4j)), (3, -2.0j)):
        X = F / (wn**2 - (k * W) ** 2 + 2j * zeta * wn * k * W)
        exact += np.array([X, 1j * k * W * X])
    assert np.allclose(y, exact.real, rtol=0, atol=1e-12 * np.max(np.abs(exact))), (y, exact.real)
    import diffrax

    sol = diffrax.diffeqsolve(diffrax.ODETerm(f), diffrax.Dopri8(), 0.0, period, 1e-3, jnp.asarray(y),
                              stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-13))
    assert np.allclose(np.asarray(sol.ys[-1]), y, rtol=0, atol=1e-8 * np.max(np.abs(y)))


@pytest.mark.parametrize("zeta", [0.05, -0.05])
def test_shooting_finds_the_periodic_state_and_its_stability(zeta):
    """periodic_orbit on a forced oscillator (9.5 Hz, forced at 10 Hz) from rest: the exact
    periodic state at t = 0 (1e-9 of its size), the largest Floquet multiplier exp(-zeta wn T)
    (1e-4), and d x(0) / d F (the forcing's amplitude) = Re X / F through the implicit-function
    step (1e-7); with negative damping the same cycle exists but repels: not ok (the caller lets
    that speed settle instead)."""
    import diffrax

    from beltjax.orders import periodic_orbit
    from beltjax.orders.shooting import held

    wn, period = 2 * np.pi * 9.5, 0.1
    W = 2 * np.pi / period

    def orbit(F):
        def field(p):
            return lambda t, y, args: jnp.stack([y[1], -wn**2 * y[0] - 2 * zeta * wn * y[1] + p * jnp.cos(W * t)])

        ts = period * jnp.arange(32) / 32
        ctrl = diffrax.PIDController(rtol=1e-10, atol=1e-12)
        return periodic_orbit(field(F), field(held(F)), jnp.zeros(2), period, ts, diffrax.Dopri8(), ctrl, 100_000, 1)

    F = 3.0
    (y, info), dx = jax.jit(lambda F: (orbit(F), jax.grad(lambda F: orbit(F)[0][0])(F)))(F)
    X = F / (wn**2 - W**2 + 2j * zeta * wn * W)
    exact = np.array([X.real, (1j * W * X).real])
    assert np.allclose(np.asarray(y), exact, rtol=0, atol=1e-9 * np.max(np.abs(exact)))
    assert abs(float(info["multiplier"]) / np.exp(-zeta * wn * period) - 1) < 1e-4
    assert abs(float(dx) - X.real / F) < 1e-7 * abs(X.real / F)
    assert float(info["ok"]) == (1.0 if zeta > 0 else 0.0)


def test_a_neutral_cycle_is_a_steady_state_without_gradients():
    """The forced oscillator of the test above beside a direction that barely decays (z'' + 0.1 z'
    + 1e-8 z = 0, multiplier 1 - 1e-8 a cycle, as an arm that dry friction holds wherever it
    stopped): the multiplier's estimate reads above 1 by its bias (ln cond / 2^20), so the cycle
    counts as a steady state without gradients (below 1 + NEUTRAL) and is left to the settling
    transient with them (a neutral family's member has no derivative)."""
    import diffrax

    from beltjax.orders import periodic_orbit, shooting

    wn, period = 2 * np.pi * 9.5, 0.1
    W = 2 * np.pi / period

    def field(t, y, args):  # positions (x, z), then speeds (x', z')
        return jnp.stack([y[2], y[3], -wn**2 * y[0] - 2 * 0.05 * wn * y[2] + 3.0 * jnp.cos(W * t),
                          -0.1 * y[3] - 1e-8 * y[1]])

    ts = period * jnp.arange(32) / 32
    ctrl = diffrax.PIDController(rtol=1e-10, atol=1e-12)
    got = {g: jax.jit(lambda: periodic_orbit(field, field, jnp.zeros(4), period, ts, diffrax.Dopri8(), ctrl,
                                             100_000, 2, gradients=g))() for g in (False, True)}
    mult = float(got[False][1]["multiplier"])
    assert 1.0 < mult < 1.0 + shooting.NEUTRAL, mult
    assert float(got[False][1]["ok"]) == 1.0 and float(got[True][1]["ok"]) == 0.0
    # the gradient path converged to the same cycle and refused it for its multiplier alone
    assert float(got[True][1]["multiplier"]) > 1.0
    assert float(got[True][1]["residual"]) <= shooting.TOLERANCE
    X = 3.0 / (wn**2 - W**2 + 2j * 0.05 * wn * W)
    assert abs(float(got[False][0][0]) - X.real) < 1e-8 * abs(X)


def test_a_predicted_cycle_is_confirmed_by_its_recorded_change():
    """The caller's check of a cycle the Newton loop stopped on by prediction: an attracting
    cycle's recorded change must be within PREDICT_CHECK (1 - mu), a neutral one's (estimate at
    least 1) within the loop's TOLERANCE; a cycle the loop converged on is not checked again."""
    from beltjax.orders.shooting import PREDICT_CHECK, TOLERANCE, prediction_confirmed

    def ok(change, mu, predicted=1.0):
        return bool(prediction_confirmed(jnp.asarray(change), jnp.asarray(mu), jnp.asarray(predicted)))

    assert ok(0.5 * TOLERANCE, 1.0 + 3e-7) and not ok(2 * TOLERANCE, 1.0 + 3e-7)  # neutral
    slow = 1.0 - 1e-6  # slowly attracting: the check tightens with 1 - mu, not the neutral one's
    assert not ok(0.5 * TOLERANCE, slow) and ok(0.5 * PREDICT_CHECK * 1e-6, slow)
    assert ok(0.5 * PREDICT_CHECK * 0.5, 0.5) and not ok(2 * PREDICT_CHECK * 0.5, 0.5)
    assert ok(1.0, 1.5, predicted=0.0)


def test_shooting_without_gradients_stops_on_newtons_prediction():
    """A hardening Duffing oscillator forced near its resonance (Newton needs several iterations):
    with gradients=False the loop stops on the prediction (a small step from the quadratic range),
    with fewer variational cycles than the converged loop (one here), and the cycle from its state
    repeats within PREDICT_CHECK (1 - mu), as the caller checks, and agrees with the converged
    loop's state to 1e-6 of the motion; differentiating a response case run that way raises,
    naming the setting."""
    import diffrax

    from beltjax.orders import periodic_orbit, shooting
    from beltjax.orders.shooting import held

    period = 0.1
    W = 2 * np.pi / period

    def field(F):
        return lambda t, y, args: jnp.stack([y[1], -(2 * np.pi * 9.0) ** 2 * y[0] * (1 + 4.0 * y[0] ** 2)
                                             - 2 * 0.05 * 2 * np.pi * 9 * y[1] + F * jnp.cos(W * t)])

    ts = period * jnp.arange(64) / 64
    ctrl = diffrax.PIDController(rtol=1e-10, atol=1e-12)

    def orbit(gradients):
        return periodic_orbit(field(1000.0), field(held(1000.0)), jnp.zeros(2), period, ts, diffrax.Dopri8(), ctrl,
                              100_000, 1, gradients)

    (y_ref, full), (y, lean) = jax.jit(lambda: (orbit(True), orbit(False)))()
    assert float(full["ok"]) == float(lean["ok"]) == 1.0 and float(full["predicted"]) == 0.0
    assert float(lean["predicted"]) == 1.0 and float(lean["iterations"]) < float(full["iterations"])
    sol = diffrax.diffeqsolve(diffrax.ODETerm(field(1000.0)), diffrax.Dopri8(), 0.0, period, period / 64, y,
                              saveat=diffrax.SaveAt(ts=ts), stepsize_controller=ctrl)
    cycle = np.asarray(sol.ys)
    end = diffrax.diffeqsolve(diffrax.ODETerm(field(1000.0)), diffrax.Dopri8(), 0.0, period, period / 64, y,
                              stepsize_controller=ctrl).ys[-1]
    change = float(shooting.change_over_cycle(y, end, cycle, 1, 1e-10, 1e-12))
    assert change <= shooting.PREDICT_CHECK * (1 - float(lean["multiplier"]))
    motion = np.ptp(cycle, axis=0)
    assert np.all(np.abs(np.asarray(y) - np.asarray(y_ref)) <= 1e-6 * motion)

    sc = loads_scene(SCENE)
    lean_settings = orders.for_scene(sc, orders.Settings(samples=32, max_order=4.0, gradients=False))
    path = "tensioner.damping"
    c0 = float(parameters.get_value(sc, path))
    with pytest.raises(ValueError, match="gradients"):
        jax.jit(jax.grad(lambda c: orders.steady_case(sc, {path: c}, 600.0, 1.0, lean_settings)["arm_angle_deg:p2p"]))(
            c0)  # raised while tracing (op by op, the statics would first run with tangents: 19 s against 2.6)


def test_step_budget_ends_a_solve_per_case(monkeypatch):
    """StepBudget, vmapped with a budget per case: a case whose budget (5 steps) runs out ends with
    max_steps_reached after exactly 5 steps; one with room ends as the bare controller does (the
    same steps, the state to 1e-12).  In periodic_orbit, a Newton iterate whose cycle takes more
    than BUDGET_FACTOR times the first cycle's steps is given up (not ok, so the speed settles)
    after that cycle (with the shipped factor the same Duffing orbit converges: the test above)."""
    import diffrax

    from beltjax.orders import periodic_orbit, shooting
    from beltjax.orders.shooting import StepBudget, held

    W = 2 * np.pi / 0.1

    def field(F):
        return lambda t, y, args: jnp.stack([y[1], -(2 * np.pi * 9.0) ** 2 * y[0] * (1 + 4.0 * y[0] ** 2)
                                             - 2 * 0.05 * 2 * np.pi * 9 * y[1] + F * jnp.cos(W * t)])

    ctrl = diffrax.PIDController(rtol=1e-10, atol=1e-12)

    def solve(budget):
        sol = diffrax.diffeqsolve(diffrax.ODETerm(field(1000.0)), diffrax.Dopri8(), 0.0, 0.1, 0.1 / 64,
                                  jnp.zeros(2), stepsize_controller=StepBudget(ctrl, budget), throw=False)
        return sol.ys[-1], sol.stats["num_steps"], sol.result == diffrax.RESULTS.successful

    y, steps, good = jax.jit(jax.vmap(solve))(jnp.array([5, 100_000]))
    bare = diffrax.diffeqsolve(diffrax.ODETerm(field(1000.0)), diffrax.Dopri8(), 0.0, 0.1, 0.1 / 64, jnp.zeros(2),
                               stepsize_controller=ctrl)
    assert list(np.asarray(steps)) == [5, int(bare.stats["num_steps"])] and list(np.asarray(good)) == [False, True]
    assert np.allclose(np.asarray(y[1]), np.asarray(bare.ys[-1]), rtol=1e-12, atol=0)  # (vmapped: other fusion)

    ts = 0.1 * jnp.arange(16) / 16

    def lean(F):
        return periodic_orbit(field(F), field(held(F)), jnp.zeros(2), 0.1, ts, diffrax.Tsit5(), ctrl, 100_000, 1,
                              False)

    # vmapped, a case that converges sooner idles while the other iterates on: each gives what it
    # gives alone (its iterations and each cycle's steps; its state to the integration's tolerance)
    (yb, ib), one = jax.jit(jax.vmap(lean))(jnp.array([10.0, 1000.0])), jax.jit(lean)
    for j, F in enumerate([10.0, 1000.0]):
        y1, i1 = one(F)
        assert float(ib["ok"][j]) == float(i1["ok"]) == 1.0
        assert np.array_equal(np.asarray(ib["cycle_steps"][j]), np.asarray(i1["cycle_steps"]))
        assert np.allclose(np.asarray(yb[j]), np.asarray(y1), rtol=1e-8, atol=1e-12)
    assert float(ib["iterations"][0]) < float(ib["iterations"][1])  # (the first did idle)

    # the shipped factor lets this orbit converge in several iterations (the test above); a factor
    # of 0.5 puts any cycle after the first over budget (read when traced: a fresh program)
    monkeypatch.setattr(shooting, "BUDGET_FACTOR", 0.5)
    info = jax.jit(lambda: periodic_orbit(field(1000.0), field(held(1000.0)), jnp.zeros(2), 0.1, ts,
                                          diffrax.Tsit5(), ctrl, 100_000, 1, False)[1])()
    assert list(np.asarray(info["cycle_steps"][2:])) == [0] * (shooting.MAX_ITERATIONS - 2)
    assert 0.5 * float(info["cycle_steps"][0]) <= float(info["cycle_steps"][1])  # ended at the budget
    assert float(info["ok"]) == 0.0 and float(info["iterations"]) == 2.0


def test_speeds_the_shooting_gives_up_settle(monkeypatch):
    """response_over_speed's passes (with the compiled batch replaced by a stand-in that records
    its calls): a speed whose shooting found no attracting cycle runs the settling transient for
    settle_s, one still unsettled then runs RETRY_FACTOR x longer; meta says which method gave
    each speed and keeps the shooting's Floquet multiplier; the statuses follow the last pass; a
    speed past the critical speed is flagged so, not run again (its transient would only exhaust
    its steps)."""
    from beltjax.orders import run as orders_run

    calls = []

    def fake_batch(settings, keys, single=False):
        def fn(scene, x, rpm, settle):
            rpm = np.asarray(rpm)
            calls.append((settings.method, float(np.asarray(settle)[0]), rpm.tolist()))
            if settings.method == "shooting":  # 600 and 900 rpm: no attracting cycle (multiplier 1.2)
                settling = np.where(np.isin(rpm, (600.0, 900.0)), np.inf, 1e-9)
                mult = np.where(np.isin(rpm, (600.0, 900.0)), 1.2, 0.5)
            else:  # the settling transient: 600 rpm settles only after the longer run
                settling, mult = np.where(float(np.asarray(settle)[0]) > 1.0, 1e-4, 0.5) + 0 * rpm, np.nan + 0 * rpm
            one = np.ones_like(rpm)
            cycles = np.outer(one, [5.0, 6.0, 7.0, 0, 0, 0, 0, 0] if settings.method == "shooting" else np.zeros(8))
            return {"settling": settling, "solver_ok": one, "converged": one, "overloaded": 0 * one,
                    "supercritical": 1.0 * (rpm == 900.0),
                    "min_span_force_N": 100 * one, "steps": 10 * one, "t_end_s": 0.1 * one,
                    "shooting_iterations": 3 * one, "shooting_cycle_steps": cycles, "floquet_multiplier": mult, "arm_angle_deg:p2p": rpm / 1000,
                    "hub_forces_N": np.zeros((len(rpm), 4, 3, 2)), "t_s": np.zeros((len(rpm), 4)),
                    "max_friction_needed": np.zeros((len(rpm), 3))}
        return fn

    monkeypatch.setattr(orders_run, "_batch", fake_batch)
    asked = []  # the fallback passes ask where to run (on an accelerator: a few speeds on the host's CPU);
    # here the first pass runs where the batch runs (padded to the chunk), the second on the host (one batch)
    monkeypatch.setattr(orders_run, "fallback_device", lambda n, hybrid=False: None if asked.append(n) or len(asked) == 1
                        else jax.devices("cpu")[0])
    res = orders.response_over_speed(loads_scene(SCENE), [500.0, 600.0, 700.0, 900.0], settle_s=1.0, chunk=4)
    assert asked == [1, 1]
    assert [c[:2] for c in calls] == [("shooting", 1.0), ("settle", 1.0), ("settle", orders.run.RETRY_FACTOR)]
    assert calls[1][2] == [600.0] * 4 and calls[2][2] == [600.0]  # only the speed given up (padded to the chunk)
    assert res.meta["methods"] == ["shooting", f"settle {orders.run.RETRY_FACTOR:g} s", "shooting", "shooting"]
    assert res.meta["floquet_multipliers"] == [0.5, 1.2, 0.5, 1.2] and res.meta["rerun_speeds"] == 1
    assert res.meta["shooting_cycle_steps"][1] == [5, 6, 7, 0, 0, 0, 0, 0]  # the shooting's, kept: why it gave up
    assert res.status == ["ok", "ok", "ok", "supercritical"] and res.settling[1] == 1e-4


def test_a_failed_rerun_keeps_the_settled_numbers(monkeypatch):
    """A speed whose settling transient ended unsettled and whose longer re-run then failed (its
    solver stopped) keeps the first run's numbers, flagged not_settled, and meta says so; a
    re-run that fails after a shooting that gave up leaves the failure (no transient's state to
    keep).  The same rule (orders.run.replaced_by) serves a sweep's response."""
    from beltjax.orders import run as orders_run

    def fake_batch(settings, keys, single=False):
        def fn(scene, x, rpm, settle):
            rpm, long = np.asarray(rpm), float(np.asarray(settle)[0]) > 1.0
            one = np.ones_like(rpm)
            shoot = settings.method == "shooting"
            return {"settling": (np.inf if shoot else 0.1) * one, "solver_ok": (0.0 if long else 1.0) * one,
                    "converged": one, "supercritical": 0 * one, "overloaded": 0 * one, "min_span_force_N": 100 * one,
                    "steps": 10 * one, "t_end_s": 0.1 * one, "shooting_iterations": 3 * one,
                    "shooting_cycle_steps": np.zeros((len(rpm), 8)), "floquet_multiplier": np.nan * one,
                    "arm_angle_deg:p2p": (np.nan if long else 1.0) * one + (2.0 if shoot else 0.0),
                    "hub_forces_N": np.zeros((len(rpm), 4, 3, 2)), "t_s": np.zeros((len(rpm), 4)),
                    "max_friction_needed": np.zeros((len(rpm), 3))}
        return fn

    monkeypatch.setattr(orders_run, "_batch", fake_batch)
    monkeypatch.setattr(orders_run, "fallback_device", lambda n, hybrid=False: None)
    scene = loads_scene(SCENE)
    got = orders.response_over_speed(scene, [600.0], settle_s=1.0, chunk=1,
                                     settings=orders.Settings(method="settle"))
    assert got.status == ["not_settled"] and got.stats["arm_angle_deg:p2p"][0] == 1.0
    assert got.meta["methods"] == [f"settle 1 s (its {orders.run.RETRY_FACTOR:g} s re-run failed)"]
    shot = orders.response_over_speed(scene, [600.0], settle_s=1.0, chunk=1)  # shooting, settle 1 s, then 4 s
    assert shot.status == ["not_settled"] and shot.stats["arm_angle_deg:p2p"][0] == 1.0
    assert orders.run.replaced_by([False, False, True], [True, False, True]).tolist() == [False, True, True]


def test_fallback_device(monkeypatch):
    """Where a fallback pass runs: the default device on a CPU backend; on an accelerator the host's
    CPU for at most HOST_FALLBACK_MAX speeds or cases, the accelerator for more; the hybrid model's
    passes on the host's CPU whatever their size (a GPU runs its small implicit steps no faster)."""
    from beltjax.orders import run as orders_run

    monkeypatch.setattr(orders_run.jax, "default_backend", lambda: "cpu")
    assert orders.fallback_device(1) is None and orders.fallback_device(1000, hybrid=True) is None
    monkeypatch.setattr(orders_run.jax, "default_backend", lambda: "gpu")
    assert orders.fallback_device(orders_run.HOST_FALLBACK_MAX).platform == "cpu"
    assert orders.fallback_device(orders_run.HOST_FALLBACK_MAX + 1) is None
    assert orders.fallback_device(1000, hybrid=True).platform == "cpu"


def test_an_unknown_start_is_refused():
    """A misspelt Settings.start is an error naming the key, through the command's path and
    through the differentiable over_speed (never the rest start in its place)."""
    sc = loads_scene(SCENE)
    bad = orders.Settings(start="linaer")
    with pytest.raises(orders.OrdersError, match="start"):
        orders.response_over_speed(sc, [600.0], settings=bad)
    with pytest.raises(ValueError, match="start"):
        orders.over_speed(sc, {}, jnp.asarray([600.0]), 1.0, orders.for_scene(sc, bad))


def test_cycle_of_half_orders():
    """Half orders make a cycle of two revolutions; thirds of three; none stays 1."""
    def revs(*n):
        text = _small("".join(_order(x, 0.1) for x in n))
        if not n:  # no excitation: the effect that would carry it is left out (listed, it is refused)
            text = text.replace(', "speed_fluctuation"]', "]")
        return orders.cycle_revolutions(loads_scene(text))

    assert revs() == 1 and revs(2.0, 4.0) == 1
    assert revs(1.5, 3.0) == 2
    assert revs(0.5, 1.0 / 3.0) == 6
    S = orders.Settings(revolutions=2, max_order=2.0)
    assert S.orders() == [0.5, 1.0, 1.5, 2.0]


def test_command_writes_its_files(tmp_path, capsys):
    """beltjax orders: exit 0, the table, orders.json / .csv / .npz and the figures."""
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    assert cli.main(["orders", str(scene), "--rpm", "500:700:100", "--settle-s", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "largest arm motion" in text and "3 speeds 500-700 rpm" in text
    data = json.loads((out / "orders.json").read_text())
    assert data["status"] == ["ok"] * 3 and len(data["stats"]["arm_angle_deg:p2p"]) == 3
    head = (out / "orders.csv").read_text().splitlines()[0].split(",")
    assert head[:2] == ["rpm", "status"] and "arm_angle_deg:order_2" in head
    assert "span_tensions_N[crank-tensioner]:p2p" in head
    for name in ("orders.npz", "order_maps.png", "envelopes.png", "hub_loci.png"):
        assert (out / name).stat().st_size > 0


@pytest.mark.parametrize("change, key", [
    (lambda t: t.replace("mean_Nm = 5.0", "mean_Nm = 5.0\nt_end_s = 1.0"), "torque[0]"),
    (lambda t: t.replace("mean_Nm = 5.0", "mean_Nm = 5.0\namplitude_Nm = 1.0\nfrequency_hz = 10.0"),
     "torque[0].amplitude_Nm"),
    (lambda t: t.replace("order = 2.0", "frequency_hz = 20.0"), "fluctuation[0]"),
    (lambda t: t.replace("order = 2.0", "order = 2.05"), "fluctuation[0]"),  # no cycle of <= 8 revolutions
    (lambda t: t.replace("speed_rpm = 600.0", "speed_rpm = 600.0\nacceleration_rpm_per_s = 100.0"),
     "pulley.crank.acceleration_rpm_per_s"),
])
def test_what_has_no_steady_state_is_refused(tmp_path, capsys, change, key):
    """One line naming the key, exit 2, no outputs."""
    scene = tmp_path / "s.toml"
    scene.write_text(change(SCENE))
    out = tmp_path / "out"
    assert cli.main(["orders", str(scene), "--rpm", "500:700:100", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0], err
    assert not out.exists()


@pytest.mark.parametrize("args, key", [
    (["--rpm", "0:700:100"], "rpm"),
    (["--rpm", "500:700:100", "--samples", "8"], "samples"),
    (["--rpm", "500:700:100", "--max-order", "100"], "max_order"),
    (["--rpm", "500:700:100", "--settle-s", "-1"], "settle-s"),
    (["--rpm", "500:700:100", "--method", "shootin"], "method"),
])
def test_bad_arguments(tmp_path, capsys, args, key):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    assert cli.main(["orders", str(scene), *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0], err
    assert not out.exists()


def test_failed_speeds_are_blank_and_reported(tmp_path, batched):
    """Speeds whose transient failed carry NaN, not the failed run's numbers (a speed of 1e-300 rpm
    hit max_steps with an arm swing of inf), and a run whose every speed failed prints its summary
    and writes its files (it raised on an all-NaN slice)."""
    import copy

    from beltjax.orders import command, run

    stats = run.blank_failed(batched.stats, ["ok", "solver_failed", "not_converged"])
    for k, v in stats.items():
        if k != "t_s":
            assert np.all(np.isnan(v[1:])) and np.array_equal(v[0], batched.stats[k][0], equal_nan=True), k
    assert np.array_equal(stats["t_s"], batched.stats["t_s"])
    # one policy with the sweeps: a flag on a computed cycle keeps its numbers, an operating point
    # past the critical speed leaves none (as a sweep's supercritical case)
    stats = run.blank_failed(batched.stats, ["span_slack", "not_settled", "supercritical"])
    for k, v in stats.items():
        if k != "t_s":
            assert np.array_equal(v[:2], batched.stats[k][:2], equal_nan=True) and np.all(np.isnan(v[2])), k
    res = copy.copy(batched)
    res.status = ["solver_failed"] * len(res.rpm)
    res.stats = run.blank_failed(batched.stats, res.status)
    text = command.summary(res)
    assert "solver failed: 500-700 rpm" in text and "largest span tension swing: none" in text
    assert "largest arm motion: none" in text and "nan" in text.splitlines()[-1]
    assert all(f.stat().st_size > 0 for f in command.write(res, tmp_path, "every speed failed"))


def test_sweep_response_output_equals_the_response(tmp_path, batched):
    """beltjax sweep's response output: each case's steady state is response_over_speed's of the
    scene with that case's values (a tolerance study of the tensioner's damping and the belt
    length; the references run through the fixture's compiled batch, the values set on the scene)."""
    from beltjax import parameters, sweep

    sc = loads_scene(SCENE)
    values = {"tensioner.damping": np.array([0.08, 0.12]), "belt.length": np.array([1.786, 1.789])}
    res = sweep.evaluate(sc, values, ("statics", "response"), settle_s=1.0)
    assert list(res["status"]) == ["ok", "ok"]
    cols = sweep.columns(sc, res)
    at = SPEEDS.index(600.0)
    for i in range(2):
        case = parameters.set_values(sc, {k: v[i] for k, v in values.items()})
        one = orders.response_over_speed(case, SPEEDS, settle_s=1.0, chunk=len(SPEEDS))
        assert abs(cols["arm_p2p_deg"][i] - one.channel("arm_angle_deg", "p2p")[at]) < 1e-7
        assert np.allclose(res["response_span_p2p_N"][i], one.channel("span_tensions_N", "p2p")[at], rtol=1e-7)
    assert abs(cols["arm_p2p_deg"][0] - cols["arm_p2p_deg"][1]) > 0.1  # the tolerances move the arm's motion
    # a traced scene cannot give the response's settings (its cycle is read from its values): a clear error
    from beltjax.sweep.batch import case_outputs

    with pytest.raises(ValueError, match="needs its settings"):
        jax.jit(lambda s: case_outputs(s, {}, ("response",)))(sc)


def test_sweep_response_settles_where_the_shooting_gave_up(monkeypatch):
    """beltjax sweep's response output: a case whose shooting found no attracting cycle (here made
    so by a stand-in around the real chunk runner, for the first case) runs again with the
    settling transient, alone, and gets its result: response_over_speed's with the settling method
    (the fallback rule and passes are orders.needs_rerun and orders.fallback_passes, one for both);
    one that failed for another cause first (here made supercritical) is not run again."""
    from beltjax import parameters, sweep
    from beltjax.sweep import batch

    real, passes = batch._run_local, []

    def run_local(scene, chunks, rpm, opts, *args):
        got = real(scene, chunks, rpm, opts, *args)
        passes.append((opts.response.method, float(chunks[0][batch.SETTLE_COLUMN][0]),
                       sum(len(next(iter(c.values()))) for c in chunks)))
        if opts.response.method == "shooting":  # as a case the shooting gave up: not settled
            cases = iter([("not_settled", 0.0), ("supercritical", 1.0)])
            for r in got:  # the chunks, in order
                for i in range(len(r["code"])):
                    status, past = next(cases)
                    r["response_settling"][i], r["code"][i] = np.inf, sweep.STATUS.index(status)
                    r["response_rerun"][i] = orders.needs_rerun(dict(settling=np.inf, solver_ok=1.0, converged=1.0,
                                                                     supercritical=past, overloaded=0.0))
        return got

    monkeypatch.setattr(batch, "_run_local", run_local)
    host = []  # a fallback of a few cases runs on the host's CPU where the sweep runs on an accelerator
    monkeypatch.setattr(orders, "fallback_device", lambda n: host.append(n) or jax.devices("cpu")[0])
    sc = loads_scene(SCENE)
    values = {"tensioner.damping": np.array([0.08, 0.12]), "belt.length": np.array([1.786, 1.789])}  # as above
    res = sweep.evaluate(sc, values, ("statics", "response"), settle_s=1.0)
    assert passes == [("shooting", 1.0, 2), ("settle", 1.0, 1)] and host == [1]  # settled: no longer pass
    case = parameters.set_values(sc, {k: v[0] for k, v in values.items()})
    one = orders.response_over_speed(case, [600.0], settle_s=1.0, settings=orders.Settings(method="settle"))
    assert abs(res["response_arm_p2p_deg"][0] - one.channel("arm_angle_deg", "p2p")[0]) < 1e-9
    assert abs(res["response_settling"][0] / one.settling[0] - 1) < 1e-2  # (a ratio of small differences)
    assert one.settling[0] < orders.SETTLE_TOL and list(res["status"]) == ["ok", "supercritical"]


def test_sweep_settling_passes_share_one_program(monkeypatch):
    """A case still unsettled after the settling pass runs RETRY_FACTOR x longer with the same
    compiled batch: the settling time is a column of the batch, not a static option (the passes'
    options are equal, so beltjax.sweep.batch._batch_fn gives the same jitted function, whose
    shapes are equal too).  Here the shooting and the first settling pass are made to miss by a
    stand-in, as in the test above (whose programs this one reuses); short passes, for a cheap test."""
    from beltjax import sweep
    from beltjax.sweep import batch

    real, passes = batch._run_local, []

    def run_local(scene, chunks, rpm, opts, size, *args):
        got = real(scene, chunks, rpm, opts, size, *args)
        settle = float(chunks[0][batch.SETTLE_COLUMN][0])
        passes.append((opts, settle, size))
        if settle < 0.05 * orders.run.RETRY_FACTOR:  # not settled yet: run again
            for r in got:
                r["response_settling"][:], r["code"][:] = np.inf, sweep.STATUS.index("not_settled")
                r["response_rerun"][:] = True
        return got

    monkeypatch.setattr(batch, "_run_local", run_local)
    monkeypatch.setattr(orders, "fallback_device", lambda n: jax.devices("cpu")[0])  # as above (its programs)
    values = {"tensioner.damping": np.array([0.08]), "belt.length": np.array([1.786])}
    res = sweep.evaluate(loads_scene(SCENE), values, ("statics", "response"), settle_s=0.05)  # (short: a cheap test)
    methods = [(o.response.method, t) for o, t, _ in passes]
    assert methods == [("shooting", 0.05), ("settle", 0.05), ("settle", 0.05 * orders.run.RETRY_FACTOR)]
    assert passes[1][0] == passes[2][0] and passes[1][2] == passes[2][2]  # one program, one shape
    assert np.isfinite(res["response_settling"][0]) and np.isfinite(res["response_arm_p2p_deg"][0])  # its result
    settled = res["response_settling"][0] <= orders.SETTLE_TOL  # (0.2 s need not settle it) and its status says so
    assert list(res["status"]) == (["ok"] if settled else ["not_settled"])


def test_gradient_over_speed_and_optimize_arm_motion():
    """beltjax optimize's arm_motion objective (the arm's largest peak-to-peak over 500-700 rpm,
    three speeds): its gradient in the tensioner's damping and spring rate, by reverse mode through
    the statics and the adaptive transients (beltjax.orders.over_speed), matches central
    differences to 1e-5; Adam then raises the damping and cuts the arm's motion."""
    from beltjax import optimize

    sc = loads_scene(SCENE)
    spec = {"steps": 6, "min_steps": 6, "starts": 1, "learning_rate": 0.2,
            "variable": [{"parameter": "tensioner.damping", "lower": 0.05, "upper": 2.0},
                         {"parameter": "tensioner.spring_stiffness", "lower": 15.0, "upper": 30.0}],
            "objective": [{"kind": "arm_motion", "rpm": [500.0, 700.0], "speeds": 3, "settle_s": 0.5}]}
    problem = optimize.parse(spec, sc)
    work = optimize.working_scene(sc, problem)
    vg = optimize._compiled(optimize._loss_key(problem))  # the optimiser's own compiled value and gradient
    rpm = jnp.asarray(optimize.sample_rpm(problem))
    masks = jnp.asarray(optimize.problem_masks(work, problem))
    x0 = np.array([0.1, 21.14])

    def value(x):
        (v, _), g = vg(jnp.asarray(x / problem.scales), work, rpm, masks)
        return float(v), np.asarray(g) / problem.scales  # d loss / d x

    v0, g0 = value(x0)
    assert v0 > 0.5
    for i in range(2):
        h = 1e-4 * x0[i]
        up, down = x0.copy(), x0.copy()
        up[i] += h
        down[i] -= h
        fd = (value(up)[0] - value(down)[0]) / (2 * h)
        assert abs(g0[i] - fd) < 1e-5 * abs(fd), (i, g0[i], fd)
    res = optimize.optimise(sc, problem)
    name = "objective[0] arm_motion"
    assert res.x[0] > res.x0[0]
    assert res.terms[name] < 0.8 * res.terms0[name]
    bad = dict(spec, objective=[{"kind": "arm_motion", "rpm": [0.0, 700.0]}])
    with pytest.raises(optimize.OptimizeError, match=r"objective\[0\]\.rpm"):
        optimize.parse(bad, sc)
