"""What the belt's creep and gross slip (effect ``belt_slip``) change, and what they cost.

Run: ``python benchmarks/bench_belt_slip.py`` (about 3 min); writes
``benchmarks/results/belt_slip.json``.

(1) Within the capacity: the eight-pulley drive (rotational, 1 s at idle, Dopri8 rtol 1e-6)
    with and without ``belt_slip``: steps, wall time after compilation, real-time factor; what
    creep changes: each pulley's mean speed against the nominal rolling (the creep speed loss),
    the mean span tensions, the friction (creep) power.
(2) Past the capacity: the rotational two-pulley bench (crank at 800 rpm, alternator loaded to
    1.1 times its capstan limit 2 F_0 R tanh(mu theta / 2) from t = 0.02 s) for belt.slip_speed
    v_r = 1 to 1e4 m/s: steps and wall time, the torque the sliding arc carries against the
    limit (the regularisation's excess, |g'| / v_r), and the alternator's deceleration against
    the unregularised (M - M_max) / J.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import json
import math
import time
from pathlib import Path

import numpy as np

from beltjax import statics, transient
from beltjax.scene import loads_scene

ROOT = Path(__file__).resolve().parents[1]
MU = 0.3


def fead(slip: bool):
    text = (ROOT / "scenes" / "fead_8pulley.toml").read_text()
    if slip:
        text = text.replace('effects = ["transport"', 'effects = ["belt_slip", "transport"', 1)
    return loads_scene(text)


def bench(torque: float, more: str = "", belt: str = ""):
    text = (ROOT / "scenes" / "two_pulley_T400.toml").read_text()
    text = text.replace("driven = false", "driven = true").replace("speed_rpm = 0.0", "speed_rpm = 800.0", 1)
    text = text.replace('fidelity = "ancf"', 'fidelity = "rotational"')
    text = text.replace("static_tension = 400.0", f"static_tension = 400.0\nfriction_coefficient = {MU}\n{belt}")
    text = text.replace('effects = ["transport"]', 'effects = ["belt_slip"]')
    return loads_scene(text + f'\n[[torque]]\npulley = "alternator"\nmean_Nm = {torque}\n' + more)


def timed(sc, t_end, **kw):
    transient.simulate(sc, t_end, **kw)  # compile
    t0 = time.perf_counter()
    res = transient.simulate(sc, t_end, **kw)
    return res, time.perf_counter() - t0


def main():
    info = _common.machine_info()
    print(_common.machine_line(info), flush=True)
    print("(1) eight-pulley drive, rotational, 1 s at idle (Dopri8 rtol 1e-6), after compilation")
    runs = {}
    for slip in (False, True):
        res, wall = timed(fead(slip), 1.0)
        runs[slip] = (res, wall)
        print(f"  belt_slip {'on ' if slip else 'off'}: {res.meta['steps']:>6} steps {wall:6.2f} s "
              f"({1.0 / wall:.2f}x real time)", flush=True)
    sc = fead(True)
    order = list(sc.route.order)
    half = runs[True][0].t >= 0.5
    nominal = np.mean(runs[False][0].channels["pulley_speeds_rpm"][half], axis=0)
    creeping = np.mean(runs[True][0].channels["pulley_speeds_rpm"][half], axis=0)
    loss = 1 - creeping / nominal
    t_off = np.mean(runs[False][0].channels["span_tensions_N"][half], axis=0)
    t_on = np.mean(runs[True][0].channels["span_tensions_N"][half], axis=0)
    power = float(np.mean(runs[True][0].channels["friction_power_W"][half]))
    print(f"  {'pulley':<16} {'creep speed loss [%]':>21}")
    for name, x in zip(order, loss):
        print(f"  {name:<16} {100 * x:>21.3f}")
    print(f"  mean span tensions change by at most {np.max(np.abs(t_on - t_off)):.3g} N; creep power {power:.3g} W "
          f"(of {float(np.mean(np.abs(runs[True][0].channels['drive_torques_Nm'][half, 0]))) * 800 * math.pi / 30:.0f} W "
          "driving the belt)")
    within = dict(steps={str(k): int(v[0].meta["steps"]) for k, v in runs.items()},
                  wall_s={str(k): v[1] for k, v in runs.items()},
                  creep_speed_loss=dict(zip(order, loss.tolist())), max_mean_tension_change_N=float(
                      np.max(np.abs(t_on - t_off))), creep_power_W=power)

    print("\n(2) two-pulley bench, alternator at 1.1x its capstan limit from t = 0.02 s, 0.1 s run, after compilation")
    sc0 = bench(6.0)
    st = statics.analyse_statics(sc0)
    theta = math.radians(st.friction["alternator"]["wrap_deg"])
    R, J = float(sc0.pulley("alternator").radius), float(sc0.pulley("alternator").inertia)
    m_max = 2 * 400.0 * R * math.tanh(MU * theta / 2)
    more = f'\n[[torque]]\npulley = "alternator"\nmean_Nm = {1.1 * m_max - 6.0}\nt_start_s = 0.02\n'
    exact = 0.1 * m_max / J
    print(f"  capstan limit {m_max:.4g} N m; unregularised deceleration {exact:.4g} rad/s^2")
    print(f"  {'v_r [m/s]':>10} {'steps':>7} {'wall [s]':>9} {'carried / limit - 1':>20} {'slip speed [m/s]':>17} "
          f"{'decel / exact':>14}")
    rows = []
    for vr in (1.0, 10.0, 100.0, 1e3, 1e4):
        res, wall = timed(bench(6.0, more, f"slip_speed = {vr}"), 0.1, output_dt=1e-3)
        c, t = res.channels, res.t
        late = t > 0.05
        F = c["span_forces_N"][late]
        excess = float(np.mean(R * (F[:, 1] - F[:, 0]) / m_max - 1))
        w = np.abs(c["pulley_speeds_rpm"][late, 1]) * math.pi / 30
        decel = -np.polyfit(t[late], w, 1)[0]
        slip = float(np.mean(c["slip_speeds_m_s"][late, 1]))
        rows.append(dict(slip_speed=vr, steps=int(res.meta["steps"]), wall_s=wall, excess=excess,
                         mean_slip_speed=slip, decel_over_exact=decel / exact))
        print(f"  {vr:>10g} {res.meta['steps']:>7} {wall:>9.2f} {excess:>20.3e} {slip:>17.3g} {decel / exact:>14.3f}",
              flush=True)
    out = ROOT / "benchmarks" / "results" / "belt_slip.json"
    out.write_text(json.dumps(dict(machine=info, fead=within, overload=dict(capstan_limit_Nm=m_max, runs=rows)),
                              indent=1))
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
