"""A tolerance study of the dynamic response (``beltjax sweep`` with the ``response`` output): what
the batched shooting of many parameter variants costs, on a CPU or a GPU.

Run: ``python benchmarks/bench_sweep_response.py`` (about 2 min on a 2-core CPU: 16 cases) or, on
a GPU, ``--cases 1024``; writes ``benchmarks/results/<name>.json`` (default
``sweep_response_<backend>``).

The cases are the worked example's (``scenes/sweeps/fead_friction_tolerance.toml`` on
``scenes/fead_8pulley_friction.toml``: the eight-pulley drive with the dry-friction tensioner at
800 rpm, belt length, tensioner friction and spring rate and the alternator's inertia drawn within
their bands), ``--cases`` of them (the file's seed).  ``sweep.evaluate`` runs twice with the default
chunk (a CPU shoots one case at a time, an accelerator all of them in one lock-step batch): the
first call compiles, the second is timed (holding ``--lock FILE``, if given, as bench_orders.py).  The cases whose shooting found no attracting cycle
settle by transient (``beltjax.orders.fallback_passes``) within both calls.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import dataclasses
import time
from pathlib import Path

import jax
import numpy as np

from beltjax import sweep
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "fead_8pulley_friction.toml"
SPEC = ROOT / "scenes" / "sweeps" / "fead_friction_tolerance.toml"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=16)
    ap.add_argument("--chunk", type=int, default=0, help="cases per compiled batch (default: the sweep's)")
    ap.add_argument("--name", default="", help="results/<name>.json (default sweep_response_<backend>)")
    ap.add_argument("--lock", default="", help="a lock file held while timing (benchmarks run side by side)")
    args = ap.parse_args()
    info = _common.machine_info()
    backend = jax.default_backend()
    print(_common.machine_line(info), flush=True)
    scene = load_scene(SCENE)
    spec = dataclasses.replace(sweep.load_spec(SPEC), samples=args.cases)
    values = sweep.cases(scene, spec)
    calls = []
    for label in ("first call (compiles)", "timed"):
        with _common.exclusive(args.lock if label == "timed" else None):
            t0 = time.perf_counter()
            out = sweep.evaluate(scene, values, spec.outputs, chunk=args.chunk or None, settle_s=spec.settle_s)
            calls.append(time.perf_counter() - t0)
        print(f"{label}: {calls[-1]:.1f} s", flush=True)
    status = {s: int(np.sum(out["status"] == s)) for s in sorted(set(out["status"]))}
    arm = out["response_arm_p2p_deg"]
    row = dict(cases=args.cases, chunk=args.chunk or None, first_call_s=calls[0], wall_s=calls[1],
               cases_per_s=args.cases / calls[1], status=status,
               arm_p2p_deg=dict(mean=float(np.nanmean(arm)), min=float(np.nanmin(arm)), max=float(np.nanmax(arm))),
               least_slip_margin=float(np.nanmin(out["response_min_slip_margin"])))
    print(f"{args.cases} cases in {calls[1]:.1f} s = {row['cases_per_s']:.2f} cases/s (first call {calls[0]:.1f} s); "
          f"status {status}; arm p2p {row['arm_p2p_deg']['min']:.3f}-{row['arm_p2p_deg']['max']:.3f} deg", flush=True)
    path = _common.save_json(args.name or f"sweep_response_{backend}",
                             dict(machine=info, backend=backend, scene=SCENE.name, sweep=SPEC.name, rows=[row]))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
