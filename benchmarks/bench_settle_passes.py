"""What a sweep's settling passes cost when a case needs the longest one: the wall time of each
pass of ``sweep.evaluate`` (``response`` output) on one case of the dry-friction tensioner's drive
whose shooting and first settling pass are made to miss (a stand-in around the chunk runner marks
them not settled, as tests/test_orders.py does), so that it runs ``RETRY_FACTOR`` x ``settle_s``.

Run: ``python benchmarks/bench_settle_passes.py`` (about 1-2 min; a fresh process, nothing
compiled); writes ``benchmarks/results/<name>.json`` (default ``settle_passes``).  The code before
the settling time became a traced column of the batch (``git worktree add /tmp/old 5f306f7`` and
``PYTHONPATH=/tmp/old python benchmarks/bench_settle_passes.py --name settle_passes_5f306f7``)
compiled the longest pass anew.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import time
from pathlib import Path

import numpy as np

from beltjax import orders, sweep
from beltjax.scene import load_scene
from beltjax.sweep import batch

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "fead_8pulley_friction.toml"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--name", default="settle_passes", help="results/<name>.json")
    args = ap.parse_args()
    info = _common.machine_info()
    print(_common.machine_line(info), flush=True)
    real, passes = batch._run_local, []

    def run_local(scene, chunks, rpm, opts, size, *rest):
        t0 = time.perf_counter()
        got = real(scene, chunks, rpm, opts, size, *rest)
        column = getattr(batch, "SETTLE_COLUMN", None)  # (the code before: a static option)
        settle = float(chunks[0][column][0]) if column else opts.settle_s
        passes.append(dict(method=opts.response.method, settle_s=settle, wall_s=time.perf_counter() - t0))
        print(f"pass {len(passes)}: {passes[-1]['method']} {settle:g} s: {passes[-1]['wall_s']:.1f} s", flush=True)
        if settle < orders.run.RETRY_FACTOR:  # made to miss: run again
            for r in got:
                r["response_settling"][:], r["code"][:] = np.inf, sweep.STATUS.index("not_settled")
                r["response_rerun"][:] = True
        return got

    batch._run_local = run_local
    t0 = time.perf_counter()
    out = sweep.evaluate(load_scene(SCENE), {"tensioner.friction_moment": np.array([0.8])}, ("statics", "response"),
                         settle_s=1.0)
    total = time.perf_counter() - t0
    print(f"whole sweep {total:.1f} s; status {list(out['status'])}", flush=True)
    path = _common.save_json(args.name, dict(machine=info, scene=SCENE.name, passes=passes, total_s=total,
                                             status=list(out["status"])))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
