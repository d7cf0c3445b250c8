"""How the rotational model's error grows over a long run, per tolerance: why its default rtol is 1e-6.

Run: ``python benchmarks/bench_long_run_error.py`` (about 1 min).  Writes
``benchmarks/results/long_run_error.json``.

The solver comparison of ``bench_transient.py`` measures errors over a 0.5 s window, where Dopri8
at rtol 1e-4 is adequate (1 %).  An undamped oscillation's error is mostly phase error, which
grows with the run; the thesis' simulations last up to 10 s.  Here the two rotational benches
of ``bench_transient.py`` (two-pulley at T = 600 N and the tensioner bench, stage 2; crank driven
at 600 rpm, alternator turned 2 deg at t = 0, no damping) run for 10 s with Dopri8 at rtol 1e-4,
1e-5 and 1e-6 (atol = 1e-3 rtol), the same equations and initial state as ``simulate``, in one
diffrax call each, against rtol 1e-12 (atol 1e-15).  Error: per state, max |y - y_ref| over the
samples (every 1 ms) up to t, over the range of y_ref; the largest over the states.
"""

from __future__ import annotations

import dataclasses
import sys
import time

import diffrax
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from _common import machine_info, machine_line, save_json, table

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))
from bench_transient import make_scene  # noqa: E402

from beltjax import transient  # noqa: E402
from beltjax.scene import Initial  # noqa: E402

T_END = 10.0
CHECKPOINTS = (0.5, 2.0, 10.0)
RTOLS = (1e-4, 1e-5, 1e-6)


@eqx.filter_jit
def _run(scene, inst, y0, ts, rtol, atol):
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(transient.vector_field(scene, inst)), diffrax.Dopri8(), t0=ts[0], t1=ts[-1], dt0=1e-4,
        y0=y0, saveat=diffrax.SaveAt(ts=ts), stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=2_000_000, throw=False,
    )
    return sol.ys, sol.result._value, sol.stats["num_steps"]


def main():
    info = machine_info()
    print(machine_line(info))
    ts = jnp.linspace(0.0, T_END, int(round(T_END / 1e-3)) + 1)
    results, rows = [], []
    for label, base in (("rotational two-pulley", "two_pulley_T600"), ("rotational tensioner bench", "tensioner_bench_stage2")):
        sc = make_scene(base=base, fidelity="rotational", driven_rpm=600, rotation={"alternator": 2.0})
        inst, qi0, qd0 = transient.initial_state(sc)
        sc0 = dataclasses.replace(sc, initial=Initial())
        y0 = jnp.concatenate([qi0, qd0])
        ref, code, n_ref = _run(sc0, inst, y0, ts, jnp.asarray(1e-12), jnp.asarray(1e-15))
        assert int(code) == 0, "reference run failed"
        ref = np.asarray(ref)
        span = np.ptp(ref, axis=0)
        for rtol in RTOLS:
            t0 = time.perf_counter()
            ys, code, n = _run(sc0, inst, y0, ts, jnp.asarray(rtol), jnp.asarray(rtol * 1e-3))
            ys = np.asarray(ys)
            wall = time.perf_counter() - t0
            assert int(code) == 0, f"rtol {rtol} failed"
            err_t = np.max(np.abs(ys - ref) / span, axis=1)
            errs = {f"{c:g} s": float(err_t[ts <= c + 1e-9].max()) for c in CHECKPOINTS}
            results.append(dict(model=label, rtol=rtol, atol=rtol * 1e-3, steps=int(n), reference_steps=int(n_ref),
                                wall_s=wall, errors=errs))
            rows.append([label, f"{rtol:g}", int(n)] + [f"{e:.1e}" for e in errs.values()])
    title = (f"Dopri8, undamped release from 2 deg at 600 rpm, {T_END:g} s: max error of the states up to t "
             "(fraction of their range) against rtol 1e-12")
    txt = table(["model", "rtol", "steps"] + [f"up to {c:g} s" for c in CHECKPOINTS], rows, title)
    print(txt)
    path = save_json("long_run_error", dict(results=results, tables=[txt]))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
