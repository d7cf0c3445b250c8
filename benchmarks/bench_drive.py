"""Whole drives: statics, modal analysis and Campbell diagram of the thesis' benches.

Run: ``python benchmarks/bench_drive.py``; writes ``benchmarks/results/bench_drive.json``.

Targets of issue 3 (after compilation, 2-core machine): statics of the two-pulley
bench (16 elements per span) under 0.5 s, its modal analysis under 50 ms, a
100-speed Campbell diagram under 2 s; compile times reported separately.

Measured entry points (all jitted; the scene is an argument, so every number of
the scene can change without recompiling):

* statics     ``statics._statics_core`` (Newton + outputs) — what ``analyse_statics`` runs
* modal       ``drive_modal.modes_at`` (linearisation by autodiff + eigh, at the equilibrium)
* modal+      the whole ``drive_modal.analyse_modes`` (adds the labels, numpy)
* Campbell    ``campbell.campbell_frequencies`` over 100 speeds (vmapped, chunks of 32)
* Campbell, tracked  ``campbell.analyse_campbell`` (what ``beltjax campbell`` runs): the same
  batch with mode shapes, modes tracked across speeds and labelled from their shapes (numpy)

Accuracy against the mesh: the two-pulley bench at T = 600 N with 4, 8, 16 and
24 elements per span against 32 (first 20 modes).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import dataclasses
import time
from pathlib import Path

import jax
import numpy as np

from beltjax import campbell, drive, drive_modal, statics
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]


def _scene(name, **model):
    sc = drive.canonical(load_scene(ROOT / "scenes" / f"{name}.toml"))
    if model:
        sc = dataclasses.replace(sc, model=dataclasses.replace(sc.model, **model))
    return sc


def main():
    info = _common.machine_info()
    print(_common.machine_line(info))
    rows, results = [], {}
    for name in ("two_pulley_T600", "tensioner_bench_stage2"):
        sc = _scene(name)
        _, c_st = _common.time_first_call(statics._statics_core, sc, 0.0)
        t_st = _common.time_steady(statics._statics_core, sc, 0.0)
        out, _ = statics._statics_core(sc, 0.0)
        _, c_mo = _common.time_first_call(drive_modal.modes_at, sc, out["qi"], out["inst"], 0.0, False)
        t_mo = _common.time_steady(drive_modal.modes_at, sc, out["qi"], out["inst"], 0.0, False)
        t_full = _common.time_steady(drive_modal.analyse_modes, sc, repeats=7)
        results[name] = dict(
            n_independent=drive.n_independent(sc), statics=t_st, statics_first_call_s=c_st,
            modal=t_mo, modal_first_call_s=c_mo, analyse_modes=t_full,
        )
        rows.append([name, drive.n_independent(sc), _common.fmt_time(t_st["median_s"]),
                     _common.fmt_time(t_mo["median_s"]), _common.fmt_time(t_full["median_s"]),
                     _common.fmt_time(c_st), _common.fmt_time(c_mo)])
    t1 = _common.table(["scene", "coords", "statics", "modal (jit)", "analyse_modes", "statics 1st call",
                        "modal 1st call"], rows, "Statics and modal analysis (after compilation)")
    print(t1)

    sc = _scene("two_pulley_T200", effects=("transport",))
    rpm = np.linspace(0.0, 2500.0, 100)
    t0 = time.perf_counter()
    campbell.campbell_frequencies(sc, rpm, 20)
    first = time.perf_counter() - t0
    t_c = _common.time_steady(campbell.campbell_frequencies, sc, rpm, 20, repeats=5, max_total_s=10.0)
    results["campbell_100_speeds"] = dict(scene="two_pulley_T200 + transport", n_modes=20, steady=t_c,
                                          first_call_s=first)
    t0 = time.perf_counter()
    campbell.analyse_campbell(sc, rpm, n_modes=20)
    first_tr = time.perf_counter() - t0
    t_tr = _common.time_steady(campbell.analyse_campbell, sc, rpm, n_modes=20, repeats=5, max_total_s=20.0)
    results["campbell_tracked_100_speeds"] = dict(scene="two_pulley_T200 + transport", n_modes=20, steady=t_tr,
                                                  first_call_s=first_tr)
    t2 = _common.table(["entry point", "speeds", "modes", "time", "per speed", "first call (compile)"],
                       [["campbell_frequencies (sorted)", 100, 20, _common.fmt_time(t_c["median_s"]),
                         _common.fmt_time(t_c["median_s"] / 100), _common.fmt_time(first)],
                        ["analyse_campbell (tracked, labelled)", 100, 20, _common.fmt_time(t_tr["median_s"]),
                         _common.fmt_time(t_tr["median_s"] / 100), _common.fmt_time(first_tr)]],
                       "Campbell diagram of two_pulley_T200 + transport (vmapped statics + gyroscopic modes)")
    print(t2)

    base = _scene("two_pulley_T600")
    f_ref = np.asarray(jax.jit(drive_modal.frequencies)(dataclasses.replace(
        base, model=dataclasses.replace(base.model, elements_per_span=32)), 0.0))[:20]
    mesh_rows, mesh = [], []
    for n in (4, 8, 16, 24):
        sc = dataclasses.replace(base, model=dataclasses.replace(base.model, elements_per_span=n))
        fn = jax.jit(drive_modal.frequencies)
        _, first = _common.time_first_call(fn, sc, 0.0)
        t = _common.time_steady(fn, sc, 0.0, repeats=11)
        f = np.asarray(fn(sc, 0.0))[:20]
        err = np.abs(f[1:] / f_ref[1:] - 1)
        mesh.append(dict(elements=n, max_rel_error=float(err.max()), error_mode2=float(err[0]),
                         error_mode20=float(err[-1]), time=t, first_call_s=first))
        mesh_rows.append([n, f"{err[0]:.1e}", f"{err[-1]:.1e}", f"{err.max():.1e}",
                          _common.fmt_time(t["median_s"]), _common.fmt_time(first)])
    t3 = _common.table(["elements/span", "err mode 2", "err mode 20", "max err (modes 2-20)", "time",
                        "first call"], mesh_rows, "Two-pulley bench T = 600 N: frequencies vs 32 elements")
    print(t3)
    results["mesh"] = mesh
    path = _common.save_json("bench_drive", dict(results=results, tables=[t1, t2, t3]))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
