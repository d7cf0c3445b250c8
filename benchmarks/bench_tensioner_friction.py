"""What the tensioner's regularised dry friction changes, and what it costs.

Run: ``python benchmarks/bench_tensioner_friction.py`` (about 3 min); writes
``benchmarks/results/tensioner_friction.json``.

(1) Accuracy: the pivot's friction law (``beltjax.drive.pivot.friction_moment``, tanh(omega /
    omega_r)) on a Coulomb-damped oscillator under harmonic forcing against Den Hartog's exact
    steady state (``pivot.den_hartog``), for omega_r from a tenth to a ten-thousandth of the
    peak speed: the amplitude error and the energy per cycle against 4 F X.
(2) Cost: the eight-pulley drive (rotational, 0.5 s at idle, Dopri8 rtol 1e-6) with the
    tensioner's viscous damping replaced by 1.5 N m of dry friction, for omega_r = 0.1, 0.01
    and 0.001 rad/s: steps and wall time after compilation, and the arm's peak-to-peak swing.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import json
import math
import time
import types
from pathlib import Path

import diffrax
import jax.numpy as jnp
import numpy as np

from beltjax import transient
from beltjax.drive import pivot
from beltjax.scene import loads_scene

ROOT = Path(__file__).resolve().parents[1]


def oscillator(P, F, k, m, w, w_r, periods=6):
    """Amplitude and friction work of the last of ``periods`` cycles, from Den Hartog's state."""
    X0, phi = pivot.den_hartog(P, F, k, m, w)
    t = types.SimpleNamespace(friction_moment=F, friction_asymmetry=1.0, friction_speed=w_r, spring_preload_deg=0.0)

    def f(time_, y, args):
        x, v, e = y
        fr = pivot.friction_moment(v, x, t)
        return jnp.stack([v, (P * jnp.cos(w * time_ + phi) - k * x + fr) / m, -fr * v])

    T = 2 * math.pi / w
    ts = jnp.linspace((periods - 1) * T, periods * T, 4001)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(f), diffrax.Dopri8(), 0.0, periods * T, T / 200,
                              jnp.array([X0, 0.0, 0.0]), saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12), max_steps=500000)
    x, e = np.asarray(sol.ys[:, 0]), np.asarray(sol.ys[:, 2])
    amp = 0.5 * (x.max() - x.min())
    return X0, amp, (e[-1] - e[0]) / (4 * F * amp), int(sol.stats["num_steps"])


def fead(w_r):
    text = (ROOT / "scenes" / "fead_8pulley.toml").read_text()
    if w_r is not None:
        text = text.replace("damping = 0.5 ", f"friction_moment = 1.5\nfriction_speed = {w_r}\ndamping = 0.05 ", 1)
        text = text.replace('effects = ["transport"', 'effects = ["tensioner_friction", "transport"', 1)
    return loads_scene(text)


def main():
    info = _common.machine_info()
    print(_common.machine_line(info), flush=True)
    rows = []
    print("(1) Coulomb oscillator, m = k = P = 1: amplitude and energy per cycle against Den Hartog's exact solution")
    print(f"{'w/w_n':>6} {'F/P':>5} {'omega_r / peak speed':>21} {'exact X0':>9} {'X error':>9} {'W / 4FX - 1':>12} "
          f"{'steps':>7}")
    for r, ratio in ((0.8, 0.2), (1.6, 0.3)):
        X0 = pivot.den_hartog(1.0, ratio, 1.0, 1.0, r)[0]
        for q in (1e-1, 1e-2, 1e-3, 1e-4):
            ex, amp, wr, steps = oscillator(1.0, ratio, 1.0, 1.0, r, q * r * X0)
            rows.append(dict(r=r, F_over_P=ratio, omega_r_over_peak=q, exact=ex, amplitude_rel_error=amp / ex - 1,
                             work_over_4FX_minus_1=wr - 1, steps=steps))
            print(f"{r:>6} {ratio:>5} {q:>21.0e} {ex:>9.4f} {amp / ex - 1:>+9.2e} {wr - 1:>+12.2e} {steps:>7}",
                  flush=True)
    cost = []
    print("\n(2) eight-pulley drive, rotational, 0.5 s at idle (Dopri8 rtol 1e-6), after compilation")
    print(f"{'tensioner pivot':>32} {'steps':>7} {'wall':>8} {'arm p-p [deg]':>14}")
    for w_r in (None, 0.1, 0.01, 0.001):
        sc = fead(w_r)
        transient.simulate(sc, 0.5)
        t0 = time.perf_counter()
        res = transient.simulate(sc, 0.5)
        wall = time.perf_counter() - t0
        th = np.asarray(res.channels["arm_angle_deg"])[len(res.t) // 2:]
        name = "viscous 0.5 N m s/rad" if w_r is None else f"dry 1.5 N m, omega_r {w_r} rad/s"
        cost.append(dict(pivot=name, omega_r=w_r, steps=int(res.meta["steps"]), wall_s=wall,
                         arm_peak_to_peak_deg=float(np.ptp(th))))
        print(f"{name:>32} {res.meta['steps']:>7} {wall:>7.2f}s {np.ptp(th):>14.4g}", flush=True)
    out = ROOT / "benchmarks" / "results" / "tensioner_friction.json"
    out.write_text(json.dumps(dict(machine=info, oscillator=rows, fead=cost), indent=1))
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
