"""Element and 16-element-span elastic forces and their Jacobians (after compilation).

Run: ``python benchmarks/bench_element.py``; writes ``benchmarks/results/bench_element.json``.

Per element (vmapped over a batch of B elements):
  forces      ``ancf.elastic_forces``
  jacfwd      ``jax.jacfwd(ancf.elastic_forces)``   (= -K_t)
  hessian     ``ancf.tangent_stiffness``            (jax.hessian of the energy)
Per 16-element span (68 coordinates):
  forces                  ``span.span_elastic_forces``
  K hessian               ``jax.hessian(span.span_strain_energy)`` (dense 68x68)
  K scatter               vmapped 8x8 ``ancf.tangent_stiffness`` scattered with ``.at[].add``
  forces+K hessian        both in one jitted function
  forces+K scatter        element forces and K_t from one jacfwd pass (has_aux), both scattered
for bending "linear" and "exact".  Compile time = trace/lower + XLA compile of
``jax.jit(f).lower(...).compile()``; run time = median of repeated blocked calls.

Targets of the brief (shown, not asserted): forces + Jacobian of a 16-element
span < 1 ms after compilation; compile < 10 s per entry point.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import time

import jax
import jax.numpy as jnp
import numpy as np

from _common import fmt_time, machine_info, machine_line, save_json, table, time_compile, time_interleaved
from beltjax import ancf, span
from beltjax.ancf import Section

# bench-belt section (N, N m^2, kg/m), 16 elements over the 0.67143 m span
SECTION = Section(111190.0, 0.034, 0.12166)
SPAN_LENGTH = 0.67143
N_SPAN = 16
TENSION = 100.5
BATCHES = (16, 1024)
TARGET_RUN_S = 1e-3
TARGET_COMPILE_S = 10.0


def span_state(n_elements, seed=0):
    """A straight span at the tension's stretch plus a small random perturbation (curved)."""
    lam = span.stretch_for_tension(TENSION, SECTION.EA)
    q = np.asarray(span.straight_state(n_elements, SPAN_LENGTH, lam))
    rng = np.random.default_rng(seed)
    q = q + 1e-3 * rng.standard_normal(q.shape) * np.tile([SPAN_LENGTH, SPAN_LENGTH, 1.0, 1.0], n_elements + 1)
    L0 = SPAN_LENGTH / (n_elements * lam)
    return jnp.asarray(q), float(L0)


def element_batch(B, seed=1):
    """B perturbed element coordinate vectors (B, 8) and their reference length."""
    q, L0 = span_state(B, seed)  # a B-element span: consecutive elements are distinct
    idx = span.element_index(B)
    return q[idx], L0


def element_entry_points(bending):
    def forces(E, L):
        return jax.vmap(ancf.elastic_forces, in_axes=(0, None, None, None))(E, SECTION, L, bending)

    def jac_fwd(E, L):
        return jax.vmap(jax.jacfwd(ancf.elastic_forces), in_axes=(0, None, None, None))(E, SECTION, L, bending)

    def hess(E, L):
        return jax.vmap(ancf.tangent_stiffness, in_axes=(0, None, None, None))(E, SECTION, L, bending)

    return {"forces": forces, "jacfwd (-K_t)": jac_fwd, "hessian (K_t)": hess}


def span_entry_points(bending, n_elements):
    idx = span.element_index(n_elements)
    n = 4 * (n_elements + 1)
    rows, cols = idx[:, :, None], idx[:, None, :]

    def forces(q, L):
        return span.span_elastic_forces(q, SECTION, L, idx, bending)

    def k_hessian(q, L):
        return jax.hessian(span.span_strain_energy)(q, SECTION, L, idx, bending)

    def k_scatter(q, L):
        Ke = jax.vmap(ancf.tangent_stiffness, in_axes=(0, None, None, None))(q[idx], SECTION, L, bending)
        return jnp.zeros((n, n), q.dtype).at[rows, cols].add(Ke)

    def both_hessian(q, L):
        return forces(q, L), k_hessian(q, L)

    def both_scatter(q, L):
        def grad_and_grad(e):
            g = jax.grad(ancf.strain_energy)(e, SECTION, L, bending)
            return g, g

        Ke, ge = jax.vmap(jax.jacfwd(grad_and_grad, has_aux=True))(q[idx])
        f = jnp.zeros(n, q.dtype).at[idx].add(-ge)
        K = jnp.zeros((n, n), q.dtype).at[rows, cols].add(Ke)
        return f, K

    return {
        "forces": forces,
        "K hessian": k_hessian,
        "K scatter": k_scatter,
        "forces+K hessian": both_hessian,
        "forces+K scatter": both_scatter,
    }


def main():
    t_start = time.perf_counter()
    info = machine_info()
    print(f"Machine: {machine_line(info)}\n")
    records = []

    # ------------------------------------------------------------------ per element
    rows = []
    for bending in ("linear", "exact"):
        for B in BATCHES:
            E, L = element_batch(B)
            eps = element_entry_points(bending)
            compiled = {name: time_compile(jax.jit(fn), E, L) for name, fn in eps.items()}
            times = time_interleaved({name: (lambda c=c: c(E, L)) for name, (c, _) in compiled.items()}, rounds=31)
            for name in eps:
                ct, tm = compiled[name][1], times[name]
                rec = dict(level="element", bending=bending, entry=name, batch=B, compile=ct, run=tm,
                           per_element_s=tm["median_s"] / B)
                records.append(rec)
                rows.append([bending, name, B, fmt_time(tm["median_s"]), fmt_time(tm["median_s"] / B),
                             f"{ct['total_s']:.2f} s"])
    # consistency: jacfwd of the forces is minus the tangent stiffness
    E, L = element_batch(16)
    checks = {}
    for bending in ("linear", "exact"):
        eps = element_entry_points(bending)
        a, b = np.asarray(eps["jacfwd (-K_t)"](E, L)), np.asarray(eps["hessian (K_t)"](E, L))
        checks[f"element jacfwd vs -hessian, {bending}"] = float(np.max(np.abs(a + b)) / np.max(np.abs(b)))
    t_el = table(["bending", "entry point", "batch B", "time / batch", "time / element", "compile"], rows,
                 "Per element (vmapped over B elements)")
    print(t_el + "\n")

    # ------------------------------------------------------------------ per 16-element span
    q, L0 = span_state(N_SPAN)
    rows = []
    for bending in ("linear", "exact"):
        eps = span_entry_points(bending, N_SPAN)
        compiled = {name: time_compile(jax.jit(fn), q, L0) for name, fn in eps.items()}
        times = time_interleaved({name: (lambda c=c: c(q, L0)) for name, (c, _) in compiled.items()}, rounds=41)
        for name in eps:
            ct, tm = compiled[name][1], times[name]
            rec = dict(level="span", bending=bending, entry=name, n_elements=N_SPAN, compile=ct, run=tm)
            if name.startswith("forces+K"):
                rec["target_run_met"] = tm["median_s"] < TARGET_RUN_S
            rec["target_compile_met"] = ct["total_s"] < TARGET_COMPILE_S
            records.append(rec)
            ratio = f"{TARGET_RUN_S / tm['median_s']:.0f}x under" if name.startswith("forces+K") else ""
            rows.append([bending, name, fmt_time(tm["median_s"]), fmt_time(tm["min_s"]), f"{ct['lower_s']:.2f} s",
                         f"{ct['compile_s']:.2f} s", ratio])
        Kh = np.asarray(eps["K hessian"](q, L0))
        Ks = np.asarray(eps["K scatter"](q, L0))
        fh, _ = eps["forces+K hessian"](q, L0)
        fs, Ks2 = eps["forces+K scatter"](q, L0)
        checks[f"span K scatter vs hessian, {bending}"] = float(np.max(np.abs(Ks - Kh)) / np.max(np.abs(Kh)))
        checks[f"span K (jacfwd+aux) vs hessian, {bending}"] = float(np.max(np.abs(np.asarray(Ks2) - Kh)) / np.max(np.abs(Kh)))
        checks[f"span forces scatter vs grad, {bending}"] = float(
            np.max(np.abs(np.asarray(fs) - np.asarray(fh))) / np.max(np.abs(np.asarray(fh))))
    t_span = table(["bending", "entry point", "median", "min", "trace+lower", "XLA compile", "vs 1 ms target"], rows,
                   f"Per {N_SPAN}-element span ({4 * (N_SPAN + 1)} coordinates)")
    print(t_span + "\n")

    t_chk = table(["check", "max rel. difference"], [[k, f"{v:.1e}"] for k, v in checks.items()], "Consistency")
    print(t_chk + "\n")

    # ------------------------------------------------------------------ targets
    span_both = [r for r in records if r["level"] == "span" and r["entry"].startswith("forces+K")]
    best = min(span_both, key=lambda r: r["run"]["median_s"])
    worst_compile = max(records, key=lambda r: r["compile"]["total_s"])
    summary = {
        "forces+K 16-element span, best route": f"{best['entry']} ({best['bending']}): {fmt_time(best['run']['median_s'])}",
        "forces+K 16-element span, all < 1 ms": all(r["run"]["median_s"] < TARGET_RUN_S for r in span_both),
        "slowest compile": f"{worst_compile['level']} {worst_compile['entry']} ({worst_compile['bending']}): "
                           f"{worst_compile['compile']['total_s']:.2f} s",
        "all compiles < 10 s": all(r["compile"]["total_s"] < TARGET_COMPILE_S for r in records),
        "forces+K scatter vs hessian route speed-up": {
            b: next(r for r in span_both if r["bending"] == b and "hessian" in r["entry"])["run"]["median_s"]
            / next(r for r in span_both if r["bending"] == b and "scatter" in r["entry"])["run"]["median_s"]
            for b in ("linear", "exact")},
    }
    for k, v in summary.items():
        print(f"{k}: {v}")
    elapsed = time.perf_counter() - t_start
    print(f"\nTotal benchmark time {elapsed:.1f} s")
    path = save_json("bench_element", {
        "section": SECTION._asdict(), "span_length_m": SPAN_LENGTH, "tension_N": TENSION,
        "targets": {"forces_plus_jacobian_16_elements_s": TARGET_RUN_S, "compile_s": TARGET_COMPILE_S},
        "summary": summary, "checks": checks, "records": records,
        "tables": {"element": t_el, "span": t_span, "checks": t_chk}, "elapsed_s": elapsed,
    })
    print(f"Saved {path}")


if __name__ == "__main__":
    main()
