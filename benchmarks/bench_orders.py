"""Responses over engine speed (``beltjax orders``): what the periodic steady state at many speeds
costs, batched with vmap, on the eight-pulley drive (rotational model).

Run: ``python benchmarks/bench_orders.py`` (about 6 min on a 2-core CPU); writes
``benchmarks/results/orders_<backend>.json``.  ``--speeds N`` (default 100, 600-6000 rpm),
``--variants a,b`` (default all), ``--chunks 25,100`` (default: the default chunk, and on a CPU
also one speed at a time for the drive as shipped), ``--name`` (the results file's name).

Each case: the operating point, 1 s of transient from it (Dopri8, rtol 1e-7), one recorded cycle
(128 samples) and the settling check (speeds that had not settled run again 4x longer).  Each
row runs twice: the first call compiles, the second is timed.  Variants: the drive as shipped
(2nd and 4th crank orders falling with speed, viscous tensioner), with the alternator decoupler,
and with the dry-friction tensioner and stops.
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
    ap.add_argument("--chunks", default="")
    ap.add_argument("--name", default="", help="results/<name>.json (default orders_<backend>)")
    args = ap.parse_args()
    info = _common.machine_info()
    backend = jax.default_backend()
    print(_common.machine_line(info), flush=True)
    rpm = np.linspace(600.0, 6000.0, args.speeds)
    rows = []
    head = f"{'variant':<24} {'speeds':>6} {'chunk':>6} {'first call':>11} {'timed':>9} {'speeds/s':>9} {'steps':>12} {'flagged':>8}"
    print(head)
    for name in args.variants.split(","):
        sc = load_scene(SCENES / VARIANTS[name])
        chunks = [int(c) for c in args.chunks.split(",") if c] or [None]
        if not args.chunks and backend == "cpu" and name == "as shipped":
            chunks = [None, 1]
        for chunk in chunks:
            t0 = time.perf_counter()
            orders.response_over_speed(sc, rpm, chunk=chunk)
            first = time.perf_counter() - t0
            t0 = time.perf_counter()
            r = orders.response_over_speed(sc, rpm, chunk=chunk)
            wall = time.perf_counter() - t0
            steps = np.asarray(r.meta["steps"])
            flagged = sum(s != "ok" for s in r.status)
            row = dict(variant=name, scene=VARIANTS[name], speeds=len(rpm), chunk=r.meta["chunk"], first_call_s=first,
                       wall_s=wall, speeds_per_s=len(rpm) / wall, steps_min=int(steps.min()),
                       steps_max=int(steps.max()), rerun=r.meta["rerun_speeds"], flagged=flagged,
                       status={s: r.status.count(s) for s in set(r.status)})
            rows.append(row)
            print(f"{name:<24} {len(rpm):>6} {row['chunk']:>6} {first:>10.1f}s {wall:>8.1f}s "
                  f"{row['speeds_per_s']:>9.2f} {steps.min():>5}-{steps.max():<6} {flagged:>8}", flush=True)
    out = _common.save_json(args.name or f"orders_{backend}", dict(machine=info, backend=backend, rows=rows,
                                                      rpm=[float(rpm[0]), float(rpm[-1])], settle_s=1.0))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
