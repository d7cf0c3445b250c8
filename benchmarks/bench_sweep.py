"""Sweep throughput: many modal analyses of the two-pulley bench, batched against looped.

Run: ``python benchmarks/bench_sweep.py`` (about 5 min) or ``--quick`` (100 cases, about
1.5 min); writes ``benchmarks/results/sweep.json``.

Target (issue "Batched parametric sweeps"): 1000 modal analyses of the two-pulley bench
(thesis mesh, 16 elements per span, 130 independent coordinates) in under 60 s after
compilation, with no tracing per case.

The cases are a 40 x 25 grid of installation tension (150-650 N) and belt EI (0.02-0.05
N m^2); every case is the statics (Newton from the installed state) plus the modal analysis
(linearisation by autodiff, Cholesky + eigvalsh), 20 lowest frequencies kept.  Routes:

(a) ``sweep.evaluate``: one compiled batch, ``vmap`` over the cases in chunks of 1, 8 and 64
    (the last chunk padded: one compilation per chunk size; 1 is the default on CPU);
(b) a Python loop over the jitted single-case function (``sweep.case_outputs`` with the
    scene and the values as arguments: compiled once, one dispatch per case);
(c) re-building per case: the case's numbers closed over in a new function, so every case
    is traced and compiled again (measured on a few cases, extrapolated to all);
(d) the public one-by-one API ``drive_modal.analyse_modes`` per case (its jitted statics and
    modal functions take the scene as an argument: no recompilation, but labels, numpy
    post-processing and two dispatches per case; measured on some cases, extrapolated).

(a) and (b) are timed round-robin after compilation (best of 3 rounds), so that a load on the
shared machine hits them alike.

Campbell output: 20 cases x 51 speeds (0-2500 rpm) of the bench with the transport effect
(steady-motion statics with 4 speed steps + gyroscopic modes per point), batched over cases
and speeds, against ``campbell.campbell_frequencies`` case by case (vmapped over speeds).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import functools
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import campbell, drive, drive_modal, parameters, sweep
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = ("statics", "modal")
MODES = 20
TARGET_S = 60.0


def _grid(n_t: int, n_ei: int) -> dict[str, np.ndarray]:
    T, EI = np.meshgrid(np.linspace(150.0, 650.0, n_t), np.linspace(0.02, 0.05, n_ei), indexing="ij")
    return {"belt.static_tension": T.reshape(-1), "belt.EI": EI.reshape(-1)}


def _rate(n: int, s: float | None) -> str:
    return "-" if not s else f"{n / s:.1f}"


def batched(scene, values, chunk: int) -> tuple[dict, callable]:
    """(a) evaluate() with one compiled batch: its first chunk call (compile) and the sweep as a
    zero-argument function."""
    n = len(next(iter(values.values())))
    size = sweep._chunk_size(n, chunk, 0, None)
    full = sweep.full_values(scene, {k: v[:size] for k, v in values.items()})
    keys = tuple(sorted(full))
    fn = sweep._batch_fn(sweep._Options(OUTPUTS, MODES, False), None, keys)
    args = jnp.asarray(np.stack([np.broadcast_to(np.asarray(full[k], float), (size,)) for k in keys], axis=1))
    t0 = time.perf_counter()
    _common.block(fn(scene, args, jnp.zeros(0)))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    _common.block(fn(scene, args, jnp.zeros(0)))
    per_chunk = time.perf_counter() - t0
    info = {"chunk": size, "first_chunk_s": first, "compile_s": first - per_chunk}
    return info, lambda: sweep.evaluate(scene, values, OUTPUTS, MODES, chunk=chunk)


def looped(scene, values) -> tuple[dict, callable]:
    """(b) a Python loop over the jitted single-case function: its first call (compile) and the
    loop as a zero-argument function (returns the frequencies)."""
    n = len(next(iter(values.values())))
    single = jax.jit(functools.partial(sweep.case_outputs, outputs=OUTPUTS, modes=MODES, gyroscopic=False))
    # strongly typed float64 scalars throughout (a Python float is weakly typed: mixing the two
    # would trace and compile the function a second time)
    full = {k: np.float64(v) for k, v in sweep.full_values(scene, {k: v[0] for k, v in values.items()}).items()}
    t0 = time.perf_counter()
    _common.block(single(scene, full))
    first = time.perf_counter() - t0

    def loop():
        freqs = np.empty((n, MODES))
        for i in range(n):
            case = dict(full, **{k: np.float64(v[i]) for k, v in values.items()})
            freqs[i] = np.asarray(single(scene, case)["frequencies_hz"])
        return freqs

    return {"first_call_s": first}, loop


def interleaved(fns: dict, rounds: int) -> dict:
    """Wall time of each zero-argument function, sampled round-robin (a load on the shared
    machine hits every route alike): {name: {"walls_s", "min_s", "median_s"}}."""
    walls = {k: [] for k in fns}
    for _ in range(rounds):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            walls[k].append(time.perf_counter() - t0)
    return {k: {"walls_s": w, "min_s": min(w), "median_s": float(np.median(w))} for k, w in walls.items()}


def rebuilt(scene, values, n_cases: int, n_total: int) -> dict:
    """(c) a new function per case (the numbers closed over): trace + compile + run per case."""
    times = []
    for i in range(n_cases):
        sc = parameters.set_values(scene, {k: float(v[i]) for k, v in values.items()})
        fn = jax.jit(lambda: sweep.case_outputs(sc, {}, OUTPUTS, MODES))  # noqa: B023
        t0 = time.perf_counter()
        _common.block(fn())
        times.append(time.perf_counter() - t0)
    per = float(np.mean(times))
    return dict(measured_cases=n_cases, per_case_s=times, extrapolated_wall_s=per * n_total,
                cases_per_s=1.0 / per)


def public_api(scene, values, n_cases: int, n_total: int) -> dict:
    """(d) drive_modal.analyse_modes per case (statics + modes + labels)."""
    sc0 = parameters.set_values(scene, {k: float(v[0]) for k, v in values.items()})
    t0 = time.perf_counter()
    drive_modal.analyse_modes(sc0)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    for i in range(n_cases):
        drive_modal.analyse_modes(parameters.set_values(scene, {k: float(v[i]) for k, v in values.items()}))
    per = (time.perf_counter() - t0) / n_cases
    return dict(first_call_s=first, measured_cases=n_cases, per_case_s=per, extrapolated_wall_s=per * n_total,
                cases_per_s=1.0 / per)


def campbell_throughput(scene, values, rpm) -> dict:
    """Campbell output of sweep.evaluate against campbell.campbell_frequencies per case."""
    n = len(next(iter(values.values())))
    t0 = time.perf_counter()
    sweep.evaluate(scene, {k: v[:1] for k, v in values.items()}, ("campbell",), MODES, rpm=rpm)
    first_b = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = sweep.evaluate(scene, values, ("campbell",), MODES, rpm=rpm)
    wall_b = time.perf_counter() - t0
    t0 = time.perf_counter()
    campbell.campbell_frequencies(parameters.set_values(scene, {k: float(v[0]) for k, v in values.items()}), rpm, MODES)
    first_l = time.perf_counter() - t0
    t0 = time.perf_counter()
    F = []
    for i in range(n):
        sc = parameters.set_values(scene, {k: float(v[i]) for k, v in values.items()})
        F.append(campbell.campbell_frequencies(sc, rpm, MODES)[0])
    wall_l = time.perf_counter() - t0
    F = np.stack(F)
    # the sweep's columns follow the nominal's modes (tracked), campbell_frequencies' are sorted: each
    # tracked frequency within the sorted range must be one of the case's sorted frequencies
    T = res["campbell_hz"][:, :, 1:, None]
    near = np.nanmin(np.abs(T / F[:, :, None, 1:] - 1), axis=-1)
    inside = np.isfinite(T[..., 0]) & (T[..., 0] <= np.nanmax(F, axis=-1, keepdims=True))
    diff = float(np.max(near[inside]))
    pts = n * len(rpm)
    return dict(cases=n, speeds=len(rpm), modes=MODES,
                batched=dict(first_call_s=first_b, wall_s=wall_b, cases_per_s=n / wall_b, points_per_s=pts / wall_b,
                             chunk=sweep._chunk_size(n, None, len(rpm), None)),
                per_case=dict(first_call_s=first_l, wall_s=wall_l, cases_per_s=n / wall_l, points_per_s=pts / wall_l),
                max_rel_difference=diff)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="100 cases, one chunk size, small Campbell (~1.5 min)")
    quick = ap.parse_args().quick
    info = _common.machine_info()
    print(_common.machine_line(info))
    scene = drive.canonical(load_scene(ROOT / "scenes" / "two_pulley_T200.toml"))
    n_ind = drive.n_independent(scene)
    values = _grid(10, 10) if quick else _grid(40, 25)
    n = len(values["belt.EI"])
    print(f"two-pulley bench, {scene.model.elements_per_span} elements per span, {n_ind} independent coordinates; "
          f"{n} cases (statics + modal, {MODES} frequencies)", flush=True)

    results: dict = dict(scene="scenes/two_pulley_T200.toml", n_independent=n_ind, n_cases=n, modes=MODES,
                         quick=quick)
    rows = []
    chunks = (1,) if quick else (1, 8, 64)
    compiled, fns = {}, {}
    for chunk in chunks:
        compiled[f"a{chunk}"], fns[f"a{chunk}"] = batched(scene, values, chunk)
    compiled["b"], fns["b"] = looped(scene, values)
    ref = fns["a1"]()
    diff = float(np.nanmax(np.abs(fns["b"]()[:, 1:] / ref["frequencies_hz"][:, 1:] - 1)))
    times = interleaved(fns, rounds=2 if quick else 3)
    for k in fns:
        t = times[k]["min_s"]
        name = (f"(a) one compiled batch, vmap in chunks of {compiled[k]['chunk']}" if k != "b" else
                "(b) Python loop over the jitted single case")
        first = compiled[k]["compile_s"] if k != "b" else compiled[k]["first_call_s"]
        rows.append([name, _common.fmt_time(t), _rate(n, t), _common.fmt_time(t / n), _common.fmt_time(first),
                     f"measured, best of {len(times[k]['walls_s'])} (median {_common.fmt_time(times[k]['median_s'])})"])
        print(rows[-1], flush=True)
    rb = rebuilt(scene, values, 2 if quick else 3, n)
    rows.append(["(c) re-built per case (trace + compile each)", _common.fmt_time(rb["extrapolated_wall_s"]),
                 f"{rb['cases_per_s']:.3f}", _common.fmt_time(float(np.mean(rb["per_case_s"]))), "every case",
                 f"extrapolated from {rb['measured_cases']} cases"])
    print(rows[-1], flush=True)
    pa = public_api(scene, values, 10 if quick else 30, n)
    rows.append(["(d) analyse_modes per case (with labels)", _common.fmt_time(pa["extrapolated_wall_s"]),
                 _rate(1, pa["per_case_s"]), _common.fmt_time(pa["per_case_s"]), _common.fmt_time(pa["first_call_s"]),
                 f"extrapolated from {pa['measured_cases']} cases"])
    print(rows[-1], flush=True)
    t1 = _common.table(["route", f"{n} cases", "cases/s", "per case", "compile (first call)", "how"], rows,
                       f"{n} modal analyses of the two-pulley bench ({n_ind} coordinates), after compilation")
    best = min(times[f"a{c}"]["min_s"] for c in chunks)
    scale = 1000 / n
    met = best * scale < TARGET_S
    verdict = (f"target: 1000 modal analyses < {TARGET_S:g} s after compilation: "
               f"{best * scale:.1f} s{' (extrapolated from ' + str(n) + ' cases)' if n != 1000 else ''} -> "
               f"{'met' if met else 'NOT met'} ({TARGET_S / (best * scale):.1f}x margin); one trace + compile "
               f"per sweep shape, none per case; batched vs looped frequencies agree to {diff:.1e}")
    print(t1)
    print(verdict)
    results.update(
        batched={str(c): {**compiled[f"a{c}"], **times[f"a{c}"], "cases_per_s": n / times[f"a{c}"]["min_s"]}
                 for c in chunks},
        looped={**compiled["b"], **times["b"], "cases_per_s": n / times["b"]["min_s"]},
        rebuilt=rb, analyse_modes=pa, batched_vs_looped_max_rel_difference=diff,
        target=dict(seconds=TARGET_S, measured_1000_s=best * scale, met=met),
    )

    sc_t = drive.canonical(load_scene(ROOT / "scenes" / "two_pulley_T200.toml"))
    rpm = np.arange(0.0, 2501.0, 250.0 if quick else 50.0)
    cv = {"belt.static_tension": np.linspace(200.0, 600.0, 4 if quick else 20)}
    cb = campbell_throughput(sc_t, cv, rpm)
    t2 = _common.table(
        ["route", "cases x speeds", "time", "cases/s", "points/s", "first call (compile)"],
        [[f"sweep campbell output (chunks of {cb['batched']['chunk']} cases x {len(rpm)} speeds)",
          f"{cb['cases']} x {cb['speeds']}", _common.fmt_time(cb["batched"]["wall_s"]),
          f"{cb['batched']['cases_per_s']:.2f}", f"{cb['batched']['points_per_s']:.0f}",
          _common.fmt_time(cb["batched"]["first_call_s"])],
         ["campbell.campbell_frequencies per case", f"{cb['cases']} x {cb['speeds']}",
          _common.fmt_time(cb["per_case"]["wall_s"]), f"{cb['per_case']['cases_per_s']:.2f}",
          f"{cb['per_case']['points_per_s']:.0f}", _common.fmt_time(cb["per_case"]["first_call_s"])]],
        f"Campbell output ({MODES} modes, transport effect, steady-motion statics with 4 speed steps per point; "
        f"max relative difference {cb['max_rel_difference']:.1e})")
    print(t2)
    results["campbell"] = cb
    path = _common.save_json("sweep", dict(results=results, tables=[t1, verdict, t2]))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
