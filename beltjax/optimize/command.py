"""The ``beltjax optimize`` command: optimise, check on the scene's mesh, write the outputs."""

from __future__ import annotations

import pathlib
import time

from beltjax.scene import Scene
from beltjax.optimize.plots import _plot_campbell_band, plot_history
from beltjax.optimize.problem import load
from beltjax.optimize.report import (_describe_constraint, _value_text, check, constraint_report, evaluator,
                                     relevant_modes, unmet)
from beltjax.optimize.scenefile import optimised_scene_text
from beltjax.optimize.solver import OptimizeResult, optimise
from beltjax import outputs

#: exit status of ``beltjax optimize`` when the run ended without meeting its goal (2: bad input)
GOAL_NOT_MET = 3


def _table(result: OptimizeResult, before: dict, after: dict) -> str:
    lines = [f"{'parameter':<34} {'before':>12} {'after':>12} {'change':>12}  bounds"]
    for j, p in enumerate(result.paths):
        at = " (at bound)" if result.x[j] in (result.lower[j], result.upper[j]) else ""
        lines.append(f"{p:<34} {result.x0[j]:>12.6g} {result.x[j]:>12.6g} {result.x[j] - result.x0[j]:>+12.4g}  "
                     f"[{result.lower[j]:g}, {result.upper[j]:g}]{at}")
    lines += ["", f"{'loss term (scene mesh, exact max)':<40} {'before':>12} {'after':>12}"]
    for k in before["terms"]:
        lines.append(f"{k:<40} {before['terms'][k]:>12.5g} {after['terms'][k]:>12.5g}")
    lines.append(f"{'total':<40} {before['loss']:>12.5g} {after['loss']:>12.5g}")
    if after["constraints"]:
        lines += ["", f"{'constraint':<46} {'before':>16} {'after':>16}  satisfied (tolerance)"]
        for b, a in zip(before["constraints"], after["constraints"]):
            lines.append(f"{_describe_constraint(a):<46} {_value_text(b):>16} {_value_text(a):>16}  "
                         f"{'yes' if a['satisfied'] else 'NO'} ({a['tolerance']:g} {a['unit']})")
    for b, a in zip(before["resonance"], after["resonance"]):
        shown = ", ".join(str(k) for k in a["modes"][:6]) + (", ..." if len(a["modes"]) > 6 else "")
        lines += ["", f"resonance band {a['rpm'][0]:g}-{a['rpm'][1]:g} rpm, orders "
                  f"{', '.join(f'{k:g}x' for k in a['orders'])}, margin {a['margin_hz']:g} Hz; "
                  f"{len(a['modes'])} modes watched ({shown}):"]
        for tag, r in (("before", b), ("after", a)):
            cx = "; ".join(f"mode {c['mode']} ({c['label']}) x {c['order']:g}x at {c['rpm']:.0f} rpm, "
                           f"{c['frequency_hz']:.1f} Hz" for c in r["crossings"]) or "none"
            near = ("no watched mode" if r["closest_hz"] is None else f"closest {r['closest_hz']:.2f} Hz (mode "
                    f"{r['closest_mode']}, {r['closest_label']}, {r['closest_rpm']:.0f} rpm)")
            lines.append(f"  {tag:<6} crossings in band: {cx}; {near}"
                         + (f"; clear with margin (within {r['tolerance_hz']:g} Hz)" if r["clear"]
                            else f"; needs {r['max_need_hz']:.3g} Hz more"))
    return "\n".join(lines)


def _statics_json(st) -> dict:
    d = st.to_json()
    keep = ("span_names", "span_tensions_N", "hub_force_magnitudes_N", "wrap_angles_deg", "belt_length_m",
            "tensioner_angle_deg", "spring_moment_Nm")
    return {k: d[k] for k in keep if k in d}


def run(scene: Scene, spec_path, out, scene_path=None) -> int:
    """The ``beltjax optimize`` command: optimise, check on the scene's mesh, write the outputs.

    Writes ``optimize.json``, ``optimized_scene.toml`` (the scene file with the variables
    replaced), ``layout_before.png`` / ``layout_after.png``, ``campbell_before.png`` /
    ``campbell_after.png`` (with a resonance objective) and ``history.png`` into ``out``;
    prints the changes and whether the goal is met (on the scene's own mesh: every resonance
    band clear with its margin, every constraint within its tolerance, no overlapping pulleys),
    and a progress line to stderr every few steps.  Returns 0 when the goal is met, else
    GOAL_NOT_MET (3), with optimize.json's ``goal_met`` false and ``unmet`` listing what is
    missing and by how much.
    """
    from beltjax.plotting import plot_layout

    from beltjax.progress import Reporter, message

    t0 = time.perf_counter()
    out = pathlib.Path(out)
    problem = load(spec_path, scene)
    reporter = Reporter()  # on stderr: redrawn on a terminal, a line every few seconds elsewhere

    def progress(d):
        start = f"start {d['start']}/{d['starts']} " if d["starts"] > 1 else ""
        reporter.update(f"optimize: {start}step {d['step']}/{d['steps']}  loss {d['loss']:.5g}  result {d['best']:.5g}  "
                        f"learning rate {d['learning_rate']:.3g}  rejected {d['rejected']}",
                        final=d["step"] == d["steps"])

    res = optimise(scene, problem, progress)
    reporter.finish()
    message("optimize: checking the start and the result on the scene's mesh")
    t_check = time.perf_counter()
    n_plot = relevant_modes(problem, res.measures0["freqs_hz"], res.measures["freqs_hz"])
    before = check(scene, problem, evaluator(scene, problem, res.x0, res), n_plot)
    after = check(res.scene, problem, evaluator(res.scene, problem, res.x, res), n_plot)
    check_s = time.perf_counter() - t_check
    missing = unmet(after)
    changes = dict(zip(res.paths, (float(v) for v in res.x)))
    title = scene.description or str(scene_path or scene.source)
    src = pathlib.Path(scene_path) if scene_path is not None else pathlib.Path(scene.source)
    head = (f"# optimised by beltjax optimize ({spec_path}): "
            + ", ".join(f"{p} {a:.6g} -> {b:.6g}" for p, a, b in zip(res.paths, res.x0, res.x)) + "\n")
    text, note = optimised_scene_text(scene, changes, head, src)
    (out / "optimized_scene.toml").write_text(text, encoding="utf-8")
    files = ["optimized_scene.toml"]
    for tag, chk, sc in (("before", before, scene), ("after", after, res.scene)):
        plot_layout(sc, chk["statics"], out / f"layout_{tag}.png")
        files.append(f"layout_{tag}.png")
        if chk["campbell"] is not None:
            _plot_campbell_band(chk["campbell"], out / f"campbell_{tag}.png", f"{title} ({tag} optimisation)", problem)
            files.append(f"campbell_{tag}.png")
    plot_history(res, out / "history.png")
    files.append("history.png")
    wall = time.perf_counter() - t0
    data = dict(
        scene=str(scene_path or scene.source), spec=str(spec_path), description=problem.description,
        mesh=dict(optimisation_elements_per_span=res.working.model.elements_per_span,
                  scene_elements_per_span=scene.model.elements_per_span),
        variables=[dict(parameter=p, before=float(a), after=float(b), change=float(b - a), lower=v.lower,
                        upper=v.upper, scale=v.scale)
                   for p, a, b, v in zip(res.paths, res.x0, res.x, problem.variables)],
        optimisation=dict(loss_before=res.loss0, loss_after=res.loss, terms_before=res.terms0, terms_after=res.terms,
                          constraints_before=constraint_report(res.measures0, res.working, problem),
                          constraints_after=constraint_report(res.measures, res.working, problem)),
        check=dict(loss_before=before["loss"], loss_after=after["loss"], terms_before=before["terms"],
                   terms_after=after["terms"], constraints_before=before["constraints"],
                   constraints_after=after["constraints"], resonance_before=before["resonance"],
                   resonance_after=after["resonance"], statics_before=_statics_json(before["statics"]),
                   statics_after=_statics_json(after["statics"])),
        all_constraints_satisfied=all(c["satisfied"] for c in after["constraints"]),
        goal_met=not missing, unmet=missing, starts=res.starts,
        result=dict(history_index=res.best_index, start=res.history[res.best_index]["start"],
                    step=res.history[res.best_index]["step"]),
        steps=res.steps, rejected_steps=res.rejected, converged=res.converged, stop_reason=res.reason,
        loss_history=res.loss_history, history=res.history,
        wall_s=wall, optimisation_s=res.wall_s, first_evaluation_s=res.compile_s, check_s=check_s,
        outputs=files, note=note,
    )
    outputs.write_json(out / "optimize.json", data)
    print(f"optimised {title} with {spec_path}")
    tried = f"{len(res.starts)} starts, " if len(res.starts) > 1 else ""
    best = res.history[res.best_index]
    print(f"{tried}{res.steps} steps (last start: {res.reason}), {res.rejected} rejected; result: step "
          f"{best['step']}" + (f" (start {best['start'] + 1})" if len(res.starts) > 1 else "")
          + f"; loss {res.loss0:.5g} -> {res.loss:.5g} "
          f"({res.working.model.elements_per_span} elements per span, checked with the scene's "
          f"{scene.model.elements_per_span}); wall {wall:.1f} s: optimisation {res.wall_s:.1f} s (first "
          f"evaluation with compilation {res.compile_s:.1f} s), check and plots {wall - res.wall_s:.1f} s")
    print("")
    print(_table(res, before, after))
    if note:
        print(note)
    skipped = sum(not h["valid"] for h in res.history)
    if skipped:
        print(f"{skipped} accepted steps had overlapping pulleys: never taken as the result")
    print("")
    if not missing:
        print("goal met: every resonance band clear with its margin and every constraint within its tolerance "
              "(scene's mesh)")
    else:
        print(f"GOAL NOT MET (exit status {GOAL_NOT_MET}):")
        for u in missing:
            print(f"  {u['text']}")
    outputs.wrote([out / f for f in ["optimize.json"] + files])
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        message(f"optimize: goal not met: {missing[0]['text']}{more}")
        return GOAL_NOT_MET
    return 0
