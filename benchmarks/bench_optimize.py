"""Layout optimisation: the README's worked example (``scenes/optimize/tensioner_pivot.toml``).

Run: ``python benchmarks/bench_optimize.py`` (about 4-6 min on the 2-core machine) or
``--quick`` (30 steps on a 4-element mesh, about 2 min); writes
``benchmarks/results/optimize.json`` (and, without ``--quick``, the README figures
``benchmarks/figures/optimize_*.png``).

Target of the issue: the example (tensioner bench, 8 elements per span, 3 variables, 9 sampled
speeds, gyroscopic eigenvalues and their gradients at each) under 5 minutes end to end.

Measured:

* cold     ``beltjax.optimize.run`` in a fresh process, as ``beltjax optimize`` runs it: the
           whole command (optimisation, check on the scene's mesh, scene file, plots); the
           first value-and-gradient evaluation (tracing + XLA compilation + one evaluation) is
           reported apart;
* warm     ``optimise`` again on the same problem in the same process (compiled functions
           reused): the optimisation alone, and the time per step;
* one step ``time_steady`` of the compiled value-and-gradient function at the start.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from beltjax import optimize
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "tensioner_bench_stage2.toml"
SPEC = ROOT / "scenes" / "optimize" / "tensioner_pivot.toml"
FIGURES = Path(__file__).resolve().parent / "figures"


def _crossings(rows):
    return [f"{c['rpm']:.0f} rpm, {c['frequency_hz']:.1f} Hz, mode {c['mode']} ({c['label']})" for c in rows]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="30 steps on a 4-element mesh (about 2 min)")
    quick = ap.parse_args().quick
    info = _common.machine_info()
    print(_common.machine_line(info))
    scene = load_scene(SCENE)
    spec_path = SPEC
    tmp = Path(tempfile.mkdtemp(prefix="bench_optimize_"))
    if quick:
        text = "elements_per_span = 4\n" + SPEC.read_text().replace("steps = 150", "steps = 30")
        spec_path = tmp / "quick.toml"
        spec_path.write_text(text)

    # cold: the command end to end (compilation included)
    t0 = time.perf_counter()
    optimize.run(scene, spec_path, tmp, scene_path=SCENE)
    cold = time.perf_counter() - t0
    data = json.loads((tmp / "optimize.json").read_text())

    # warm: the optimisation again, compiled functions reused
    problem = optimize.load(spec_path, scene)
    res = optimize.optimise(scene, problem)
    per_step = np.diff([h["t_s"] for h in res.history])
    vg = optimize._compiled(optimize._loss_key(problem))
    z0 = jnp.asarray(res.x0 / problem.scales)
    rpm, masks = jnp.asarray(optimize.sample_rpm(problem)), jnp.asarray(res.masks)
    one = _common.time_steady(vg, z0, res.working, rpm, masks, repeats=11, max_total_s=5.0)

    chk = data["check"]
    rows = [
        ["end to end (cold: compile + optimise + check + plots)", _common.fmt_time(cold)],
        ["  first value-and-gradient evaluation (trace + compile + run)", _common.fmt_time(data["first_evaluation_s"])],
        ["  optimisation (cold, compilation included)", _common.fmt_time(data["optimisation_s"])],
        ["  check on the scene's mesh + scene file + plots", _common.fmt_time(cold - data["optimisation_s"])],
        ["optimisation (warm, compiled)", _common.fmt_time(res.wall_s)],
        ["  per step (median over the run)", _common.fmt_time(float(np.median(per_step)) if per_step.size else None)],
        ["one value-and-gradient evaluation (steady)", _common.fmt_time(one["median_s"])],
    ]
    t1 = _common.table(["what", "time"], rows,
                       f"Example optimisation, {res.working.model.elements_per_span} elements per span, "
                       f"{len(problem.variables)} variables, {res.steps} steps ({res.reason})")
    print(t1)
    vrows = [[v["parameter"], f"{v['before']:.6g}", f"{v['after']:.6g}", f"{v['change']:+.4g}"]
             for v in data["variables"]]
    crows = [[optimize._describe_constraint(a), optimize._value_text(b), optimize._value_text(a),
              "yes" if a["satisfied"] else "NO"] for b, a in zip(chk["constraints_before"], chk["constraints_after"])]
    t2 = _common.table(["parameter", "before", "after", "change"], vrows, "Variables")
    t3 = _common.table(["constraint", "before", "after", "satisfied"], crows,
                       "Constraints (scene's mesh, static state)")
    rb, ra = chk["resonance_before"][0], chk["resonance_after"][0]
    def row(tag, r, loss):
        return [tag, "; ".join(_crossings(r["crossings"])) or "none",
                f"{r['closest_hz']:.2f} Hz (mode {r['closest_mode']}, {r['closest_rpm']:.0f} rpm)", f"{loss:.4g}"]

    t4 = _common.table(["", "crossings in the band", "closest approach", "loss"],
                       [row("before", rb, chk["loss_before"]), row("after", ra, chk["loss_after"])],
                       f"2x crank order, {rb['rpm'][0]:g}-{rb['rpm'][1]:g} rpm, margin {rb['margin_hz']:g} Hz "
                       "(scene's mesh)")
    for t in (t2, t3, t4):
        print(t)
    if not quick:
        FIGURES.mkdir(exist_ok=True)
        for name in ("campbell_before", "campbell_after", "layout_before", "layout_after", "history"):
            shutil.copy(tmp / f"{name}.png", FIGURES / f"optimize_{name}.png")
    results = dict(
        quick=quick, scene=str(SCENE.relative_to(ROOT)), spec=str(SPEC.relative_to(ROOT)),
        elements_per_span=res.working.model.elements_per_span, variables=data["variables"],
        steps=data["steps"], converged=data["converged"], stop_reason=data["stop_reason"],
        rejected_steps=data["rejected_steps"], loss_history=data["loss_history"],
        cold=dict(end_to_end_s=cold, first_evaluation_s=data["first_evaluation_s"],
                  optimisation_s=data["optimisation_s"], check_and_plots_s=cold - data["optimisation_s"]),
        warm=dict(optimisation_s=res.wall_s, steps=res.steps, per_step_median_s=float(np.median(per_step))),
        value_and_gradient=one,
        check=dict(loss_before=chk["loss_before"], loss_after=chk["loss_after"], terms_before=chk["terms_before"],
                   terms_after=chk["terms_after"], constraints_before=chk["constraints_before"],
                   constraints_after=chk["constraints_after"], resonance_before=rb, resonance_after=ra,
                   statics_before=chk["statics_before"], statics_after=chk["statics_after"]),
        target=dict(end_to_end_under_s=300.0, met=bool(cold < 300.0)),
    )
    path = _common.save_json("optimize", dict(results=results, tables=[t1, t2, t3, t4]))
    shutil.rmtree(tmp, ignore_errors=True)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
