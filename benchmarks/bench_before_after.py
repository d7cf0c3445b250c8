"""Interleaved before/after timing of the headline transients, each call in a fresh process.

Usage::

    git worktree add /tmp/before <commit>
    python benchmarks/bench_before_after.py /tmp/before [rounds]   # about 3 min for 2 rounds

Runs ``simulate`` of the headline rotational case (two-pulley, 600 rpm, alternator +2 deg, 1 s,
median of 9 calls after the first) and hybrid case (16 elements per span, 5 N span pulse,
0.05 s, median of 6) alternately with the code of BEFORE (``PYTHONPATH``) and of this checkout,
each in a fresh process, so that a slow spell of the machine hits both: single back-to-back
runs on this machine scatter by 10-30 %.  The figure is ``meta["wall_s"] / t_end`` as in
``bench_transient.py`` (initial state and integration).  Prints one line per run and the
medians; writes results/before_after.json.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

CHILD = r'''
import sys, json
sys.path.insert(0, sys.argv[1] + "/benchmarks")
import _common  # noqa: F401
import numpy as np
from bench_transient import CASES, make_scene
from beltjax import transient
if sys.argv[2] == "rot":
    sc, w, n = make_scene(base="two_pulley_T600", fidelity="rotational", driven_rpm=600, rotation={"alternator": 2.0}), 1.0, 9
else:
    sc, w, n = make_scene(**CASES["hyb"]["scene"]), 0.05, 6
transient.simulate(sc, w)
s = [(lambda r: r.meta["wall_s"] / r.meta["t_end_s"])(transient.simulate(sc, w)) for _ in range(n)]
print(json.dumps(dict(median=float(np.median(s)), min=min(s), max=max(s))))
'''


def run(tree: Path, case: str, before: bool) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    if before:
        env["PYTHONPATH"] = str(tree)
    out = subprocess.run([sys.executable, "-c", CHILD, str(tree), case], env=env, capture_output=True, text=True,
                         check=True, cwd=tree)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv):
    before = Path(argv[0]).resolve()
    rounds = int(argv[1]) if len(argv) > 1 else 2
    after = HERE.parent
    res = {"rot": {"before": [], "after": []}, "hyb": {"before": [], "after": []}}
    for case in ("rot", "hyb"):
        for k in range(rounds):
            for which, tree in (("before", before), ("after", after)) if k % 2 == 0 else (("after", after), ("before", before)):
                r = run(tree, case, which == "before")
                res[case][which].append(r)
                print(f"{case} {which}: {r['median']:.4g} s per simulated s ({r['min']:.4g}-{r['max']:.4g})", flush=True)
    for case, d in res.items():
        b = np.median([r["median"] for r in d["before"]])
        a = np.median([r["median"] for r in d["after"]])
        print(f"{case}: before {b:.4g}, after {a:.4g} s per simulated s, after / before {a / b:.3f}")
        d["ratio"] = float(a / b)
    path = HERE / "results" / "before_after.json"
    path.write_text(json.dumps(dict(before=str(before), results=res), indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1:])
