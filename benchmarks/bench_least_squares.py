"""The three least-squares fits (damping, tensile, modal): time after compilation, first call,
and the optimum each reaches -- to compare the fits' least-squares layer before and after a change.

Run: ``python benchmarks/bench_least_squares.py [LABEL]``; writes
``benchmarks/results/least_squares[_LABEL].json`` (``LABEL`` names a variant, e.g. ``before``).

Timed (each on a shipped example dataset, in one process):
  damping   ``damping.fit_impulse`` on identification/examples/impulse (2 modes)
  tensile   ``tensile.fit_tensile`` on identification/examples/tensile_belt_B (12 records, 8 starts)
  modal     ``modal_fit.fit_modal`` on identification/examples/bench_modal (3 configurations)
The optimum is recorded as the fitted values and the final cost, so that two runs can be
compared for "same optimum" as well as for time.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import sys
import time
import tomllib

import numpy as np

from _common import HERE, fmt_time, machine_info, machine_line, save_json, table, time_first_call, time_steady

sys.path.insert(0, str(HERE.parent))

from identification import damping, modal_fit, tensile  # noqa: E402

EX = HERE.parent / "identification" / "examples"


def _section(name: str, key: str):
    folder = EX / name
    return tomllib.loads((folder / "dataset.toml").read_text())[key], folder


def _optimum(kind: str, res) -> dict:
    if kind == "damping":
        r = res.records[0]
        return {"frequency_hz": list(map(float, r.frequencies_hz)), "damping_ratio": list(map(float, r.damping_ratios))}
    if kind == "tensile":
        ea, _ = res.EA([0.01, 10.0, 60.0])
        return {"theta": list(map(float, res.theta)), "chi2": float(res.chi2), "EA_N_at_0.01_10_60_Hz": ea.tolist()}
    return {"values": list(map(float, res.values)),
            "rms_residual_hz": float(np.sqrt(np.mean([m["residual_hz"] ** 2 for m in res.modes]))),
            "iterations": int(res.iterations)}


def main():
    label = sys.argv[1] if len(sys.argv) > 1 else ""
    info = machine_info()
    print(f"Machine: {machine_line(info)}\n")
    cases = {
        "damping": (damping.fit_impulse, *_section("impulse", "impulse")),
        "tensile": (tensile.fit_tensile, *_section("tensile_belt_B", "tensile")),
        "modal": (modal_fit.fit_modal, *_section("bench_modal", "modal")),
    }
    rows, out = [], {}
    for kind, (fn, sec, folder) in cases.items():
        res, cold = time_first_call(lambda: fn(sec, folder))
        tm = time_steady(lambda: fn(sec, folder), repeats=7, max_total_s=20.0)
        opt = _optimum(kind, res)
        out[kind] = {"first_call_s": cold, "run": tm, "optimum": opt}
        rows.append([kind, fmt_time(tm["median_s"]), fmt_time(tm["min_s"]), fmt_time(cold)])
        print(f"{kind}: {opt}", flush=True)
    print()
    print(table(["fit", "median", "min", "first call (compile + run)"], rows,
                title=f"Least-squares fits after compilation{' (' + label + ')' if label else ''}"))
    name = "least_squares" + (f"_{label}" if label else "")
    print(f"\nwrote {save_json(name, {'label': label, 'fits': out})}")


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"Total benchmark time {time.perf_counter() - t0:.1f} s")
