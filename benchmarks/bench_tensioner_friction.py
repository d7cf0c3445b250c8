"""What the tensioner's regularised dry friction changes, and what it costs.

Run: ``python benchmarks/bench_tensioner_friction.py`` (about 4 min); writes
``benchmarks/results/tensioner_friction.json``.

The law (``beltjax.drive.pivot.friction_moment``) is a regularised switch model with two
regularisation parameters: tau (``friction_stick_time``, s; a held arm's speed decays at the
rate 1 / tau) and omega_r (``friction_speed``, rad/s; the band closes to the sliding moment as
the arm's speed passes it).

(1) Accuracy: a Coulomb-damped oscillator (m = k = P = 1) under harmonic forcing against Den
    Hartog's exact steady state (``pivot.den_hartog``): the amplitude error and the energy per
    cycle against 4 F X, over a grid of omega_r (a tenth to a ten-thousandth of the peak speed)
    and tau (a tenth to a hundred-thousandth of the period); and a mass the band holds (F > P
    plus the spring's force): its drift over six periods.
(2) Cost: the eight-pulley drive with the dry-friction tensioner and stops
    (``scenes/fead_8pulley_friction.toml``, rotational, 1 s at idle, Dopri8) at rtol 1e-4 and
    1e-6 for several (tau, omega_r), against the same drive with viscous damping
    (``scenes/fead_8pulley.toml``): steps and wall time after compilation (least of three), and
    the error of the arm angle and the span tensions over the second half second (max |x -
    x_ref| / peak-to-peak of x_ref) against tau = 1e-5 s, omega_r = 1e-4 rad/s at rtol 1e-8.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import json
import math
import re
import time
import types
from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import transient
from beltjax.drive import pivot
from beltjax.scene import loads_scene

ROOT = Path(__file__).resolve().parents[1]
T_END = 1.0


@jax.jit
def _oscillator(p):
    P, F, k, m, w, w_r, tau, phi, x0 = p
    t = types.SimpleNamespace(friction_moment=F, friction_asymmetry=1.0, friction_speed=w_r, friction_stick_time=tau,
                              spring_preload_deg=0.0)
    f = pivot.coulomb_oscillator(P, k, m, w, phi, t)
    T = 2 * jnp.pi / w
    ts = 6 * T * jnp.linspace(5.0 / 6.0, 1.0, 4001)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(f), diffrax.Dopri8(), 0.0, 6 * T, T / 200,
                              jnp.stack([x0, 0.0, 0.0]), saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12), max_steps=500000)
    return sol.ys, sol.stats["num_steps"]


def oscillator(P, F, w, w_r, tau, x0=None):
    """(exact amplitude, amplitude, friction work / 4 F X, steps, mean position) of the last of six
    periods, from Den Hartog's state (or from rest at x0)."""
    X0, phi = pivot.den_hartog(P, F, 1.0, 1.0, w) if x0 is None else (None, 0.0)
    ys, steps = _oscillator(jnp.array([P, F, 1.0, 1.0, w, w_r, tau, phi, X0 if x0 is None else x0]))
    x, e = np.asarray(ys[:, 0]), np.asarray(ys[:, 2])
    amp = 0.5 * (x.max() - x.min())
    return X0, amp, (e[-1] - e[0]) / (4 * F * max(amp, 1e-300)), int(steps), float(x.mean())


def _scene(name, rtol, tau=None, w_r=None):
    text = (ROOT / "scenes" / name).read_text()
    if tau is not None:
        text = re.sub(r"^friction_speed = [0-9.e-]+", f"friction_speed = {w_r}\nfriction_stick_time = {tau}", text,
                      count=1, flags=re.M)
    return _common.dopri8_at(loads_scene(text), rtol)


def main():
    info = _common.machine_info()
    print(_common.machine_line(info), flush=True)
    rows = []
    print("(1) Coulomb oscillator, m = k = P = 1, w/w_n = 1.6, F/P = 0.3: amplitude error against Den Hartog's "
          "exact solution (W / 4FX - 1 in brackets)")
    r, ratio = 1.6, 0.3
    X0 = pivot.den_hartog(1.0, ratio, 1.0, 1.0, r)[0]
    T = 2 * math.pi / r
    qts = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5)
    print(f"{'omega_r / peak speed':>21} " + " ".join(f"{'tau/T ' + format(q, '.0e'):>21}" for q in qts))
    for qw in (1e-1, 1e-2, 1e-3, 1e-4):
        cells = []
        for qt in qts:
            ex, amp, wr, steps, _ = oscillator(1.0, ratio, r, qw * r * X0, qt * T)
            rows.append(dict(r=r, F_over_P=ratio, omega_r_over_peak=qw, tau_over_period=qt, exact=ex,
                             amplitude_rel_error=amp / ex - 1, work_over_4FX_minus_1=wr - 1, steps=steps))
            cells.append(f"{amp / ex - 1:+.1e} ({wr - 1:+.0e})")
        print(f"{qw:>21.0e} " + " ".join(f"{c:>21}" for c in cells), flush=True)
    held = []
    for qt in (1e-1, 1e-2, 1e-3):
        _, amp, _, steps, mean = oscillator(1.0, 1.5, r, 1e-2, qt * T, x0=0.2)
        held.append(dict(F_over_P=1.5, x0=0.2, tau_over_period=qt, omega_r=1e-2, half_swing=amp, drift=mean - 0.2,
                         steps=steps))
    print("a mass the band holds (F/P = 1.5, from rest at x = 0.2): half-swing over the last period "
          + ", ".join(f"{h['half_swing']:.1e} (tau/T {h['tau_over_period']:.0e})" for h in held)
          + "; drift " + ", ".join(f"{h['drift']:+.1e}" for h in held), flush=True)

    print(f"\n(2) eight-pulley drive, rotational, {T_END} s at idle, Dopri8, after compilation (least of three)")
    print(f"{'tensioner pivot':>44} {'rtol':>6} {'steps':>7} {'wall':>8} {'vs real time':>13} {'error':>9}")
    ref = transient.simulate(_scene("fead_8pulley_friction.toml", 1e-8, 1e-5, 1e-4), T_END)
    cost = []
    cases = [("viscous 0.5 N m s/rad (fead_8pulley.toml)", "fead_8pulley.toml", None, None)]
    cases += [(f"dry, tau {tau:g} s, omega_r {w_r:g} rad/s", "fead_8pulley_friction.toml", tau, w_r)
              for tau, w_r in ((3e-4, 0.01), (1e-3, 0.01), (1e-4, 0.01), (3e-4, 0.001), (1e-3, 0.1))]
    for rtol in (1e-4, 1e-6):
        for name, scene, tau, w_r in cases:
            sc = _scene(scene, rtol, tau, w_r)
            res = transient.simulate(sc, T_END)  # compiles
            walls = []
            for _ in range(3):
                t0 = time.perf_counter()
                res = transient.simulate(sc, T_END)
                walls.append(time.perf_counter() - t0)
            wall = min(walls)
            err = None if tau is None else _common.transient_error(res, ref)
            cost.append(dict(pivot=name, tau=tau, omega_r=w_r, rtol=rtol, steps=int(res.meta["steps"]), wall_s=wall,
                             real_time_factor=T_END / wall, error=err))
            e = "-" if err is None else f"{err:.1e}"
            print(f"{name:>44} {rtol:>6.0e} {res.meta['steps']:>7} {wall:>7.2f}s {T_END / wall:>12.1f}x {e:>9}",
                  flush=True)
    out = ROOT / "benchmarks" / "results" / "tensioner_friction.json"
    out.write_text(json.dumps(dict(machine=info, oscillator=rows, held=held, fead=cost,
                                   reference=dict(tau=1e-5, omega_r=1e-4, rtol=1e-8, steps=int(ref.meta["steps"]))),
                              indent=1))
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
