"""The hybrid (ANCF) transient of the eight-pulley drive: wall time per simulated second, compile
time and peak memory by mesh and engine speed (issue 22's targets: 8 elements per span, response
resolved to 1 kHz, at most 30 s wall per simulated second, under 2 GB, compile under 60 s).

Usage::

    .venv/bin/python benchmarks/bench_hybrid_fead.py            # about 8 min; writes results/hybrid_fead.json
    .venv/bin/python benchmarks/bench_hybrid_fead.py --quick    # 8 elements at idle only
    .venv/bin/python benchmarks/bench_hybrid_fead.py --rerun-only   # the command's re-run, cached

The command line's re-run: ``beltjax simulate`` of the hybrid drive twice with a fresh
persistent compilation cache (the second run loads the compiled programs).

Each case runs in a fresh process (so that its peak resident memory is its own, compilation
included) on ``scenes/fead_8pulley.toml`` with ``model.fidelity = "ancf"``: the default solver
(generalized-alpha, dt = 1e-4 s, outputs every 5e-4 s: spectra to 1 kHz).  The first call
compiles (the statics of the installation and of the operating point, the integrator, the
outputs) and runs; the second call of the same scene in the same process is timed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from _common import HERE, machine_info, machine_line, save_json, table

CASE = r'''
import dataclasses, json, resource, sys, time
sys.path.insert(0, {bench!r})
import _common  # noqa: F401  (thread settings, float64)
from beltjax import transient
from beltjax.scene import load_scene

def rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

sc = load_scene({scene!r})
crank = sc.route.order[0]
pulleys = tuple(dataclasses.replace(p, speed_rpm={rpm}) if p.name == crank else p for p in sc.pulleys)
sc = dataclasses.replace(sc, pulleys=pulleys,
                         model=dataclasses.replace(sc.model, fidelity="ancf", elements_per_span={elements}))
t0 = time.perf_counter()
res = transient.simulate(sc, {t_end})
first = time.perf_counter() - t0
first_chunk = res.meta["first_chunk_s"]
rss_first = rss_mb()
t0 = time.perf_counter()
res = transient.simulate(sc, {t_end})
second = time.perf_counter() - t0
print(json.dumps(dict(first_call_s=first, first_chunk_s=first_chunk, run_s=second,
                      steps=res.meta["steps"], dt_s=res.meta["dt_s"], output_dt_s=res.meta["output_dt_s"],
                      n_independent=res.meta["n_independent"], peak_rss_mb=rss_mb(), peak_rss_first_mb=rss_first,
                      warnings=transient.run_warnings(res.meta))))
'''


def _flags(warnings: list[str]) -> str:
    """The run's warnings, each cut to its first clause (the JSON keeps them whole)."""
    return "; ".join(w.removeprefix("warning: ").split(" (")[0] for w in warnings) or "none"


def run_case(elements: int, rpm: float, t_end: float) -> dict:
    code = CASE.format(bench=str(HERE), scene=str(HERE.parent / "scenes" / "fead_8pulley.toml"), rpm=rpm,
                       elements=elements, t_end=t_end)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=HERE.parent)
    if proc.returncode != 0:
        return dict(elements=elements, rpm=rpm, t_end_s=t_end, error=proc.stderr.strip().splitlines()[-1])
    rec = json.loads(proc.stdout.strip().splitlines()[-1])
    rec.update(elements=elements, rpm=rpm, t_end_s=t_end, wall_per_simulated_s=rec["run_s"] / t_end)
    return rec


def rerun() -> dict:
    """``beltjax simulate`` of the hybrid drive (8 elements per span, 0.05 s) twice with a fresh
    persistent compilation cache: wall time of each command (s)."""
    import tempfile
    import time

    scene_text = (HERE.parent / "scenes" / "fead_8pulley.toml").read_text()
    scene_text = scene_text.replace('fidelity = "rotational"', 'fidelity = "ancf"\nelements_per_span = 8', 1)
    walls, meta = [], []
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "fead_8pulley_hybrid.toml"
        scene.write_text(scene_text)
        env = dict(os.environ, BELTJAX_CACHE=str(Path(tmp) / "cache"))
        for k in range(2):
            t0 = time.perf_counter()
            proc = subprocess.run([str(Path(sys.executable).parent / "beltjax"), "simulate", str(scene), "--t-end",
                                   "0.05", "--out", str(Path(tmp) / f"out{k}")], capture_output=True, text=True, env=env)
            walls.append(time.perf_counter() - t0)
            if proc.returncode != 0:
                return dict(error=proc.stderr.strip().splitlines()[-1])
            meta.append(json.loads((Path(tmp) / f"out{k}" / "simulation.json").read_text())["meta"])
    # the second run: its statics and start (setup_s), then its first chunk (first_chunk_s: the
    # integrator traced, fetched from the cache and run for a tenth of the simulated time)
    return dict(first_run_s=walls[0], second_run_s=walls[1], second_setup_s=meta[1]["setup_s"],
                second_first_chunk_s=meta[1]["first_chunk_s"], second_simulate_s=meta[1]["wall_s"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="8 elements per span at idle only")
    ap.add_argument("--rerun-only", action="store_true", help="only the command line's re-run with the cache")
    args = ap.parse_args()
    info = machine_info()
    print(f"Machine: {machine_line(info)}\n")
    again = rerun()
    nan = float("nan")
    print(f"beltjax simulate of the hybrid drive (8 elements per span, 0.05 s), fresh compilation cache: "
          f"first run {again.get('first_run_s', nan):.1f} s, second run {again.get('second_run_s', nan):.1f} s "
          f"(statics and start {again.get('second_setup_s', nan):.1f} s, then the first chunk "
          f"{again.get('second_first_chunk_s', nan):.1f} s) {again.get('error', '')}\n", flush=True)
    if args.rerun_only:
        print(f"wrote {save_json('hybrid_fead_rerun', dict(machine=info, rerun=again))}")
        return
    cases = [(8, 800.0, 1.0)] if args.quick else [(4, 800.0, 1.0), (8, 800.0, 1.0), (12, 800.0, 0.5),
                                                   (8, 6000.0, 0.5)]
    records, rows = [], []
    for elements, rpm, t_end in cases:
        rec = run_case(elements, rpm, t_end)
        records.append(rec)
        print(f"  {elements} elements per span, {rpm:g} rpm: {rec.get('error') or 'done'}", flush=True)
        if "error" in rec:
            rows.append([elements, f"{rpm:g}", f"{t_end:g}", "failed: " + rec["error"], "", "", "", "", ""])
            continue
        rows.append([elements, f"{rpm:g}", f"{t_end:g}", rec["n_independent"], rec["steps"],
                     f"{rec['wall_per_simulated_s']:.1f} s", f"{rec['first_chunk_s']:.0f} s / {rec['first_call_s']:.0f} s",
                     f"{rec['peak_rss_mb'] / 1024:.2f} GB", _flags(rec["warnings"])])
    headers = ["elements per span", "crank rpm", "simulated s", "coordinates", "steps (dt 1e-4 s)",
               "wall per simulated s", "compile + first chunk / first call", "peak memory", "run warnings"]
    text = table(headers, rows, title="Hybrid transient of the eight-pulley drive (generalized-alpha, outputs to 1 kHz)")
    print(text)
    path = save_json("hybrid_fead" + ("_quick" if args.quick else ""), dict(machine=info, records=records,
                                                                           rerun=again, table=text))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
