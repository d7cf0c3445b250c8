"""Where the rotational transient of the eight-pulley drive spends its time: steps against the
solver and tolerance, the vector field's cost per evaluation and its fused kernels.

Usage::

    .venv/bin/python benchmarks/bench_rotational_steps.py     # about 2 min; writes results/rotational_steps.json

On ``scenes/fead_8pulley.toml`` (rotational, 800 rpm idle, 2nd and 4th crank orders, from its
operating point), 1 s: the compiled vector field of ``beltjax.transient`` integrated by diffrax
directly (saving 1001 samples) with Dopri8, Tsit5 and Dopri5 at rtol 1e-9 ... 1e-4 (atol =
1e-3 rtol), the error against Dopri8 at rtol 1e-9 (largest over the saved samples and
coordinates, rad and rad/s); one evaluation of the vector field timed in a compiled loop of
10,000; the number of fused kernels XLA makes of it; a Dopri8 step of a trivial linear vector
field of the same size (diffrax's own cost per step).  The vector field is timed twice: with the
scene's numbers closed over as constants (XLA folds them) and as the traced arguments that
``beltjax.transient.simulate`` compiles it with (one program per drive structure, whatever the
numbers).  Then ``transient.simulate`` itself, 1 s after compilation (best of 3), on the eight-pulley
drive and its variants: with ``belt_slip``; the tensioner with dry friction, a decoupler and the
three crank orders of ``fead_8pulley_friction.toml``; the decoupler drive: steps, wall and the
real-time factor, and the share of the output channels in it.
"""

from __future__ import annotations

import dataclasses
import re
import time

import equinox as eqx

from _common import machine_info, machine_line, save_json, table

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from _common import HERE
from beltjax import drive, transient
from beltjax.scene import load_scene, loads_scene
from beltjax.transient import Initial
from beltjax.transient_outputs import _outputs

#: (label, scene file, with belt_slip)
RUNS = (("idle, 2nd and 4th orders", "fead_8pulley.toml", False),
        ("the same with belt_slip", "fead_8pulley.toml", True),
        ("friction tensioner, decoupler, 3 orders", "fead_8pulley_friction.toml", False),
        ("decoupler", "fead_8pulley_decoupler.toml", False))

SOLVERS = {"Dopri8": diffrax.Dopri8, "Tsit5": diffrax.Tsit5, "Dopri5": diffrax.Dopri5}
RTOLS = (1e-9, 1e-7, 1e-6, 1e-5, 1e-4)


def _setup():
    sc = drive.canonical(load_scene(HERE.parent / "scenes" / "fead_8pulley.toml"))
    sc = dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation, solver=transient.default_solver(sc)))
    inst, qi0, qd0 = transient.initial_state(sc)
    sc = dataclasses.replace(sc, initial=Initial())
    return sc, inst, transient.start_vector(sc, inst, qi0, qd0)


def _solve(f, solver, rtol, y0):
    @jax.jit
    def run(y0):
        sol = diffrax.diffeqsolve(diffrax.ODETerm(f), solver, 0.0, 1.0, 1e-4, y0,
                                  saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, 1.0, 1001)),
                                  stepsize_controller=diffrax.PIDController(rtol=rtol, atol=1e-3 * rtol),
                                  max_steps=200_000)
        return sol.ys, sol.stats["num_steps"]

    jax.block_until_ready(run(y0))
    t0 = time.perf_counter()
    ys, n = jax.block_until_ready(run(y0))
    return np.asarray(ys), int(n), time.perf_counter() - t0


def _per_eval(loop, *args) -> float:
    """Seconds per vector-field evaluation of a compiled loop of 5,000 (best of 7)."""
    jax.block_until_ready(loop(*args))
    best = float("inf")
    for _ in range(7):
        t0 = time.perf_counter()
        jax.block_until_ready(loop(*args))
        best = min(best, (time.perf_counter() - t0) / 5000)
    return best


def _simulate_rows():
    """transient.simulate, 1 s after compilation, on each of :data:`RUNS`."""
    rows, records = [], []
    for label, name, slip in RUNS:
        text = (HERE.parent / "scenes" / name).read_text()
        if slip:
            text = text.replace('effects = ["', 'effects = ["belt_slip", "', 1)
        sc = loads_scene(text)
        res = transient.simulate(sc, 1.0)  # compile
        wall = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            res = transient.simulate(sc, 1.0)
            wall = min(wall, time.perf_counter() - t0)
        c = drive.canonical(sc)
        c = dataclasses.replace(c, simulation=dataclasses.replace(c.simulation, solver=transient.default_solver(c)))
        inst = transient.initial_state(c)[0]
        c = dataclasses.replace(c, initial=Initial())
        t, y = jnp.asarray(res.t), jnp.asarray(res.y)
        jax.block_until_ready(_outputs(t, y, c, inst))
        t0 = time.perf_counter()
        jax.block_until_ready(_outputs(t, y, c, inst))
        out_s = time.perf_counter() - t0
        rec = dict(run=label, scene=name, belt_slip=slip, steps=res.meta["steps"], wall_s=wall,
                   real_time_factor=1.0 / wall, outputs_s=out_s)
        records.append(rec)
        rows.append([label, rec["steps"], f"{1e3 * wall:.0f} ms", f"{1.0 / wall:.1f}x", f"{1e3 * out_s:.0f} ms"])
        print(f"  {label}: {rec['steps']} steps, {1e3 * wall:.0f} ms ({1.0 / wall:.1f}x real time)", flush=True)
    return rows, records


def main():
    info = machine_info()
    print(f"Machine: {machine_line(info)}\n")
    sc, inst, y0 = _setup()
    f = transient.vector_field(sc, inst)
    rows, records, ref = [], [], None
    for name, cls in SOLVERS.items():
        for rtol in RTOLS:
            ys, n, wall = _solve(f, cls(), rtol, y0)
            if ref is None:
                ref = ys
            err = np.abs(ys - ref).max(axis=0)
            k = y0.shape[0] // 2
            rec = dict(solver=name, rtol=rtol, steps=n, wall_s=wall, max_error_angles_rad=float(err[:k].max()),
                       max_error_speeds_rad_s=float(err[k:].max()))
            records.append(rec)
            rows.append([name, f"{rtol:g}", n, f"{1e3 * wall:.0f} ms", f"{rec['max_error_angles_rad']:.1e}",
                         f"{rec['max_error_speeds_rad_s']:.1e}"])
            print(f"  {name} rtol {rtol:g}: {n} steps, {1e3 * wall:.0f} ms", flush=True)
    t_solvers = table(["solver", "rtol", "steps per simulated s", "wall", "error: angles [rad]", "speeds [rad/s]"],
                      rows, title="Eight-pulley rotational drive, 1 s at idle: steps against the solver and tolerance")

    @jax.jit
    def loop(y):
        return jax.lax.fori_loop(0, 5000, lambda i, y: y + 1e-12 * f(i * 1e-5, y, None), y)

    per_eval = _per_eval(loop, y0)
    dyn, static = eqx.partition((sc, inst), eqx.is_array)

    @jax.jit
    def loop_traced(dyn, y):  # the scene's numbers as arguments, as transient.simulate compiles it
        g = transient.vector_field(*eqx.combine(dyn, static))
        return jax.lax.fori_loop(0, 5000, lambda i, y: y + 1e-12 * g(i * 1e-5, y, None), y)

    per_eval_traced = _per_eval(loop_traced, dyn, y0)
    hlo = jax.jit(lambda y: f(0.1, y, None)).lower(y0).compile().as_text()
    kernels = len(re.findall(r"= \S+ fusion\(", hlo[hlo.index("ENTRY"):]))
    n = y0.shape[0] // 2
    K = jnp.diag(jnp.linspace(1e3, 5e3, n) ** 2)
    trivial = lambda t, y, args: jnp.concatenate([y[n:], -K @ y[:n] + jnp.sin(300.0 * t)])  # noqa: E731
    _, steps_t, wall_t = _solve(trivial, diffrax.Dopri8(), 1e-6, 0.0 * y0)
    t_vf = table(["what", "value"], [["vector field, one evaluation (numbers as constants)", f"{1e6 * per_eval:.1f} us"],
                                     ["vector field, one evaluation (numbers traced, as simulate runs it)",
                                      f"{1e6 * per_eval_traced:.1f} us"],
                                     ["its fused kernels (XLA CPU)", kernels],
                                     ["Dopri8 step of a trivial linear field of the same size",
                                      f"{1e6 * wall_t / steps_t:.1f} us"]],
                 title="The vector field and the solver's own cost")
    sim_rows, sim_records = _simulate_rows()
    t_sim = table(["eight-pulley drive, rotational, 1 s", "steps", "simulate (after compilation)", "real time",
                   "of which output channels"], sim_rows,
                  title="transient.simulate, default settings (Dopri8, rtol 1e-6, outputs at 1 kHz)")
    print(t_solvers + "\n\n" + t_vf + "\n\n" + t_sim)
    path = save_json("rotational_steps", dict(machine=info, solvers=records, vector_field_us=1e6 * per_eval,
                                              vector_field_traced_us=1e6 * per_eval_traced,
                                              fused_kernels=kernels, trivial_dopri8_step_us=1e6 * wall_t / steps_t,
                                              simulate=sim_records,
                                              tables=dict(solvers=t_solvers, vector_field=t_vf, simulate=t_sim)))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
