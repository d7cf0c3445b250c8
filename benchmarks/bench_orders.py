"""Responses over engine speed (``beltjax orders``): what the periodic steady state at many speeds
costs, batched with vmap, on the eight-pulley drive (rotational model).

Run: ``python benchmarks/bench_orders.py`` (about 15 min on a 2-core CPU); writes
``benchmarks/results/orders_<backend>.json``.  ``--speeds N`` (default 100, 600-6000 rpm),
``--variants a,b`` (default all), ``--methods shooting,settle`` (default both), ``--chunks 25,100``
(default: the method's default chunk, and on a CPU also batches of 25 shootings for the drive as
shipped), ``--name`` (the results file's name), ``--lock FILE`` (held while timing: benchmarks run
side by side on one machine time one at a time; their first calls overlap).

Each case: the operating point, then the periodic state by shooting (Newton on the one-cycle map
with its variational equations, beltjax.orders.shooting; the speeds where it does not converge to
an attracting cycle settle) or by 1 s of transient (the speeds that had not settled run again 4x
longer), both Dopri8 at rtol 1e-7 and started on the linearised drive's periodic response; one
recorded cycle (128 samples).  Each row runs twice: the first call compiles, the second is
timed.  The shooting rows also give the largest difference from the settling rows, over the
speeds both call ``ok``, of the arm's and the spans' peak-to-peak (their agreement).  Variants:
the drive as shipped (2nd and 4th crank orders falling with speed, viscous tensioner), with the
alternator decoupler, and with the dry-friction tensioner and stops.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import time
from pathlib import Path

import jax
import numpy as np

from beltjax import orders
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
VARIANTS = {
    "as shipped": "fead_8pulley.toml",
    "alternator decoupler": "fead_8pulley_decoupler.toml",
    "dry-friction tensioner": "fead_8pulley_friction.toml",
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--speeds", type=int, default=100)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--methods", default="shooting,settle")
    ap.add_argument("--chunks", default="")
    ap.add_argument("--name", default="", help="results/<name>.json (default orders_<backend>)")
    ap.add_argument("--lock", default="", help="a lock file held while timing (benchmarks run side by side)")
    ap.add_argument("--max-iterations", type=int, default=0,
                    help="the shooting's most Newton iterations (default: beltjax.orders.shooting.MAX_ITERATIONS)")
    args = ap.parse_args()
    if args.max_iterations:  # what the limit costs (benchmarks/README.md section 5g)
        from beltjax.orders import shooting

        shooting.MAX_ITERATIONS = args.max_iterations
    info = _common.machine_info()
    backend = jax.default_backend()
    print(_common.machine_line(info), flush=True)
    rpm = np.linspace(600.0, 6000.0, args.speeds)
    rows = []
    head = (f"{'variant':<24} {'method':<9} {'speeds':>6} {'chunk':>6} {'first call':>11} {'timed':>9} "
            f"{'speeds/s':>9} {'steps':>12} {'settled':>8} {'flagged':>8} {'arm p2p diff':>12} {'span p2p diff':>13}")
    print(head)
    for name in args.variants.split(","):
        sc = load_scene(SCENES / VARIANTS[name])
        runs = [(m, int(c)) for m in args.methods.split(",") for c in args.chunks.split(",") if c]
        if not runs:
            runs = [(m, None) for m in args.methods.split(",")]
            if backend == "cpu" and name == "as shipped" and ("shooting", None) in runs:
                runs.insert(runs.index(("shooting", None)) + 1, ("shooting", 25))
        got = {}
        for method, chunk in runs:
            settings = orders.Settings(method=method)
            start = [time.perf_counter()]

            def progress(done, total):  # each batch's end (the main pass, then any fallback pass)
                print(f"    {time.perf_counter() - start[0]:7.1f} s: {done}/{total} speeds of a pass", flush=True)

            t0 = time.perf_counter()
            orders.response_over_speed(sc, rpm, chunk=chunk, settings=settings, progress=progress)
            first = time.perf_counter() - t0
            print(f"  ({name}, {method}: first call {first:.1f} s)", flush=True)
            with _common.exclusive(args.lock):
                t0 = start[0] = time.perf_counter()
                r = orders.response_over_speed(sc, rpm, chunk=chunk, settings=settings, progress=progress)
                wall = time.perf_counter() - t0
            got.setdefault(method, r)
            steps = np.asarray(r.meta["steps"])
            flagged = sum(s != "ok" for s in r.status)
            settled = sum(not m.startswith("shooting") for m in r.meta["methods"]) if method == "shooting" else len(rpm)
            row = dict(variant=name, scene=VARIANTS[name], method=method, speeds=len(rpm), chunk=r.meta["chunk"],
                       first_call_s=first, wall_s=wall, speeds_per_s=len(rpm) / wall, steps_min=int(steps.min()),
                       steps_max=int(steps.max()), settled=settled, rerun=r.meta["rerun_speeds"], flagged=flagged,
                       status={s: r.status.count(s) for s in set(r.status)})
            rows.append(row)
        ref = got.get("settle")
        for row in rows[-len(runs):]:
            diff = ["", ""]
            if ref is not None and row["method"] == "shooting":
                r = got["shooting"]
                ok = (np.asarray(r.status) == "ok") & (np.asarray(ref.status) == "ok")
                d_arm = float(np.max(np.abs(r.channel("arm_angle_deg", "p2p") - ref.channel("arm_angle_deg", "p2p"))[ok]))
                d_span = float(np.max(np.abs(r.channel("span_tensions_N", "p2p")
                                             - ref.channel("span_tensions_N", "p2p"))[ok]))
                row.update(max_arm_p2p_difference_deg=d_arm, max_span_p2p_difference_N=d_span, compared=int(ok.sum()))
                diff = [f"{d_arm:.1e} deg", f"{d_span:.1e} N"]
            print(f"{name:<24} {row['method']:<9} {len(rpm):>6} {row['chunk']:>6} {row['first_call_s']:>10.1f}s "
                  f"{row['wall_s']:>8.1f}s {row['speeds_per_s']:>9.2f} {row['steps_min']:>5}-{row['steps_max']:<6} "
                  f"{row['settled']:>8} {row['flagged']:>8} {diff[0]:>12} {diff[1]:>13}", flush=True)
    from beltjax.orders import shooting

    out = _common.save_json(args.name or f"orders_{backend}", dict(machine=info, backend=backend, rows=rows,
                                                      max_iterations=shooting.MAX_ITERATIONS,
                                                      rpm=[float(rpm[0]), float(rpm[-1])], settle_s=1.0))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
