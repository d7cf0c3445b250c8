"""The eight-pulley drive's operating point and its rotational idle transient: time after
compilation and first call, both fidelities of the operating point (issue 22's speed targets).

Usage::

    python benchmarks/bench_operating_point.py       # about 2 min

Measures on ``scenes/fead_8pulley.toml``: the compiled statics of the operating point
(``statics.solve_at(..., loaded=True)``: Newton under the mean loads plus the outputs: tensions,
hubs, drive torque) and of the unloaded state, rotational and hybrid (8 elements per span);
the whole ``analyse_statics`` (both states, slip margins, checks); the rotational transient of
one simulated second at idle with the 2nd crank order (wall per simulated second, real-time
factor).  Writes results/operating_point.json.  Friction enters as the capstan assessment of
the solved state (in ``analyse_statics``); this drive's belt grips (no ``belt_slip``), so its
statics holds the arcs as installed rather than solving the running belt's compatibility.
"""

from __future__ import annotations

import dataclasses
import time

from _common import HERE, fmt_time, machine_info, machine_line, save_json, table, time_first_call, time_steady

from beltjax import drive, statics, transient  # noqa: E402
from beltjax.scene import load_scene  # noqa: E402

SCENE = HERE.parent / "scenes" / "fead_8pulley.toml"


def _fidelity(sc, fidelity: str, elements: int = 8):
    return dataclasses.replace(sc, model=dataclasses.replace(sc.model, fidelity=fidelity, elements_per_span=elements))


def main():
    t0 = time.perf_counter()
    info = machine_info()
    print(f"Machine: {machine_line(info)}\n")
    base = load_scene(SCENE)
    rows, records = [], []
    for fid in ("rotational", "ancf"):
        sc = drive.canonical(_fidelity(base, fid))
        v = float(drive.belt_speed(sc))
        for loaded in (True, False):
            name = f"{fid}: statics, {'operating point' if loaded else 'unloaded'}"
            _, first = time_first_call(lambda: statics.solve_at(sc, v, loaded))
            tm = time_steady(lambda: statics.solve_at(sc, v, loaded), repeats=15, max_total_s=10.0)
            rows.append([name, fmt_time(tm["median_s"]), fmt_time(first), drive.n_independent(sc)])
            records.append(dict(entry=name, run=tm, first_call_s=first, n_independent=drive.n_independent(sc)))
        name = f"{fid}: analyse_statics (both states, slip margins)"
        _, first = time_first_call(lambda: statics.analyse_statics(sc))
        tm = time_steady(lambda: statics.analyse_statics(sc), repeats=7, max_total_s=10.0)
        rows.append([name, fmt_time(tm["median_s"]), fmt_time(first), drive.n_independent(sc)])
        records.append(dict(entry=name, run=tm, first_call_s=first, n_independent=drive.n_independent(sc)))
    t_stat = table(["what", "after compilation", "first call", "coordinates"], rows,
                   title="Operating point of the eight-pulley drive (8 elements per span for the hybrid model)")
    print(t_stat + "\n")

    sc = load_scene(SCENE)
    t_end = 1.0
    _, first = time_first_call(lambda: transient.simulate(sc, t_end, progress=False))
    tm = time_steady(lambda: transient.simulate(sc, t_end, progress=False), repeats=3, max_total_s=60.0)
    res = transient.simulate(sc, t_end, progress=False)
    per_s = tm["median_s"] / t_end
    t_tr = table(["what", "wall per simulated s", "real-time factor", "first call (1 s)", "steps"],
                 [["rotational idle transient (dopri8)", fmt_time(per_s), f"{1.0 / per_s:.1f}x", fmt_time(first),
                   res.meta["steps"]]],
                 title="Rotational transient of the eight-pulley drive at idle (2nd crank order, loads, slip margins)")
    print(t_tr + "\n")
    elapsed = time.perf_counter() - t0
    path = save_json("operating_point", dict(
        scene=str(SCENE.relative_to(HERE.parent)), records=records,
        transient=dict(wall_per_simulated_s=per_s, real_time_factor=1.0 / per_s, first_call_s=first,
                       steps=res.meta["steps"], run=tm),
        tables=dict(statics=t_stat, transient=t_tr), elapsed_s=elapsed))
    print(f"Total benchmark time {elapsed:.1f} s\nwrote {path}")


if __name__ == "__main__":
    main()
