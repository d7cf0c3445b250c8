"""Accuracy-time atlas: what a given accuracy costs on the whole drives.

Run: ``python benchmarks/bench_atlas.py`` (7 min of CPU time; 9.7 min of wall time on the
2-core machine at a load average of 3.6-5) or ``--quick`` (about half: fewer
meshes, no Campbell study of the tensioner, no transient spot check, no tensioner effect
series); ``--parts mesh transient fidelity effects`` runs a subset; ``--replot`` redraws the
figures from ``results/atlas.json``.  Writes
``benchmarks/results/atlas.json`` and ``benchmarks/figures/atlas_*.png`` and prints the
tables.  The other scripts measure pieces (``bench_span.py``: one span against the analytic
string; ``bench_drive.py``: the drive entry points at the thesis' meshes;
``bench_transient.py``: transient solvers); this one puts accuracy and cost side by side
for the user's choices.

1. Mesh (elements per span) on the WHOLE drive: the two-pulley bench (T = 200, 400,
   600 N; the three share one compilation) and the tensioner bench.  For each mesh:
   statics (``statics._statics_core``) and modal analysis (``drive_modal.modes_at`` at
   rest, without the numpy labelling of ``analyse_modes``) after compilation, their
   compile times (``lower`` + XLA ``compile``), and the Campbell diagram
   (``campbell.campbell_frequencies``, 16 speeds 0-2500 rpm, 20 modes, one vmapped batch)
   on some meshes (compile = first call minus a later call; error against the finest of
   those meshes).  Run times are the minimum over the samples (the machine is shared).  Error of the k-th flexible
   frequency (sorted, rigid mode left out) against the finest mesh (32 elements per span;
   a Richardson extrapolation from the three finest meshes bounds that reference's own
   error) and against the bench measurements of Tables 7.2 / 7.4 / 7.6 (two-pulley) and
   7.9 (tensioner), matched through the mode labels at the finest mesh.
2. Integrator and step / tolerance on the real models: re-expressed from
   ``results/transient.json`` (``bench_transient.py``: wall time per simulated second,
   error of the response below 1 kHz against a tight reference), not re-run; a spot check
   re-runs a few settings with the current code (``bench_transient.Case``, quick windows;
   the rotational case with its reference, the hybrid one with the default solver only).
3. Rotational vs hybrid fidelity on the same scenes: statics (span tensions, hub force,
   arm angle), the torsional / tensioner modes, and a transient (thesis Simulation 1:
   alternator released from 2 deg, belt damping) run by ``transient.simulate`` with the
   default solver for both fidelities.
4. Effects: the transient right-hand side ``transient.vector_field`` of the two-pulley
   bench (16 el./span, crank driven at 600 rpm) with no effect, each effect alone, and all:
   jaxpr equations (recursive), StableHLO ops, optimised HLO instructions, XLA flops,
   compile time and run time; the static residual's jaxpr size; a short generalized-alpha
   transient for no effect / transport / all.  "Absent costs nothing": the scene with an
   effect's parameters set but the effect not listed traces to the same jaxpr text as the
   scene without them, reuses the same compiled executable (no new jit cache entry) and
   gives bit-identical forces.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import dataclasses
import json
import math
import re
import statistics
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402,F401
import numpy as np  # noqa: E402

import bench_transient as bt  # noqa: E402  (scene_text / make_scene / Case / errors: reused)
from _common import (fmt_time, machine_info, machine_line, save_json, table, time_compile,  # noqa: E402
                     time_interleaved, time_steady)
from beltjax import campbell, drive, drive_modal, statics, transient  # noqa: E402
from beltjax.scene import Scene, Simulation, load_scene, loads_scene  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
FIGURES = HERE / "figures"
REFERENCE = ROOT.parent / "shared" / "reference" / "thesis_reference.json"

RPM = np.linspace(0.0, 2500.0, 16)  # Campbell grid (one vmapped batch of 16 speeds)
N_CAMPBELL_MODES = 20
K_MODES = 20  # flexible modes whose errors are kept
KS = (4, 8, 16)  # "first k modes" shown in the tables
LEVELS = (1e-2, 1e-3, 1e-4)
ORD = re.compile(r"^(\d+)(st|nd|rd|th) (transverse|longitudinal|rotational)(.*)$")
TENSIONER_SPANS = {"T1": "alternator-crank", "T2": "crank-tensioner", "T3": "tensioner-alternator"}


def log(msg):
    print(msg, flush=True)


# --------------------------------------------------------------------------- scenes


def bench_scene(base: str, *, elements=None, fidelity=None, driven=False, effects=None) -> Scene:
    """scenes/<base>.toml (canonical) with elements per span / fidelity / crank driven at rest / effects."""
    sc = drive.canonical(load_scene(ROOT / "scenes" / f"{base}.toml")) if not driven else \
        drive.canonical(loads_scene(bt.scene_text(base=base, driven_rpm=0.0)))
    model = sc.model
    kw = {}
    if elements is not None:
        kw["elements_per_span"] = int(elements)
    if fidelity is not None:
        kw["fidelity"] = fidelity
    if effects is not None:
        kw["effects"] = tuple(effects)
    return dataclasses.replace(sc, model=dataclasses.replace(model, **kw)) if kw else sc


# --------------------------------------------------------------------------- statics + modal of one drive (memoised)

_DRIVE_CACHE: dict = {}


def drive_stats(base: str, n: int, fidelity: str = "ancf", driven: bool = False, timed: bool = True) -> dict:
    """Statics and modes (at rest) of a bench scene: compile times, steady times, results.

    Memoised per (base, n, fidelity, driven); with timed=False only the results (the
    compiled functions are shared by scenes that differ only in numbers, e.g. T200/T600)."""
    key = (base, n, fidelity, driven)
    if key in _DRIVE_CACHE and (_DRIVE_CACHE[key]["timed"] or not timed):
        return _DRIVE_CACHE[key]
    sc = bench_scene(base, elements=n, fidelity=fidelity, driven=driven)
    rec = dict(scene=base, elements=n, fidelity=fidelity, driven=driven, timed=timed,
               n_independent=drive.n_independent(sc))
    if timed:
        _, ct = time_compile(statics._statics_core, sc, 0.0)
        rec["statics_compile"] = ct
    out, info = jax.block_until_ready(statics._statics_core(sc, 0.0))
    assert float(info[0]) > 0.5, (key, info)
    if timed:
        rec["statics_time"] = time_steady(statics._statics_core, sc, 0.0, repeats=15, max_total_s=1.0)
        _, ct = time_compile(drive_modal.modes_at, sc, out["qi"], out["inst"], 0.0, False)
        rec["modal_compile"] = ct
    r = jax.block_until_ready(drive_modal.modes_at(sc, out["qi"], out["inst"], 0.0, False))
    if timed:
        rec["modal_time"] = time_steady(drive_modal.modes_at, sc, out["qi"], out["inst"], 0.0, False,
                                        repeats=15, max_total_s=1.0)
    nr = drive_modal.n_rigid_modes(sc)
    f = np.asarray(r["freqs"])
    rec.update(n_rigid=nr, freqs=f, flex=f[nr:], stable=bool(r["stable"]),
               tensions=np.asarray(out["tensions"]), hubs=np.asarray(out["hubs"]),
               theta_deg=float(np.degrees(np.asarray(out["theta"]))) if sc.tensioner is not None else None,
               _sc=sc, _out=out, _modes=r)
    _DRIVE_CACHE[key] = rec
    return rec


def labels_of(rec) -> list[str]:
    """Mode labels (drive_modal.label_modes) of a drive_stats record."""
    if "labels" not in rec:
        r, out = rec["_modes"], rec["_out"]
        rec["labels"], _ = drive_modal.label_modes(np.asarray(r["freqs"]), np.asarray(r["shapes"]), out["qi"],
                                                   rec["_sc"], out["inst"], r["J"])
    return rec["labels"]


def campbell_stats(base: str, n: int, repeats: int = 2) -> dict:
    """Campbell diagram (RPM, 20 modes, one batch): first call, later calls, frequencies."""
    sc = bench_scene(base, elements=n)
    t0 = time.perf_counter()
    f, ok, conv = campbell.campbell_frequencies(sc, RPM, N_CAMPBELL_MODES, chunk=len(RPM))
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        campbell.campbell_frequencies(sc, RPM, N_CAMPBELL_MODES, chunk=len(RPM))
        times.append(time.perf_counter() - t0)
    steady = statistics.median(times)
    return dict(first_call_s=first, times_s=times, median_s=steady, min_s=min(times),
                compile_s=max(first - steady, 0.0), freqs=np.asarray(f), all_ok=bool(np.all(ok & conv)))


# --------------------------------------------------------------------------- measured frequencies


def measured_rows(ref: dict, base: str) -> list[dict]:
    """Bench measurements (Tables 7.2/7.4/7.6, 7.9) as dicts: shape, measured, thesis, (order, kind, span)."""
    if base.startswith("two_pulley_T"):
        T = int(base.rsplit("T", 1)[1])
        rows = next(c for c in ref["two_pulley_bench"]["modal"]["cases"] if c["T"] == T)["modes"]
        table_id = {200: "7.2", 400: "7.4", 600: "7.6"}[T]
    else:
        rows = ref["tensioner_bench_stage2"]["modal"]["modes"]
        table_id = "7.9"
    out = []
    for _, thesis, meas, shape in rows:
        if meas is None:
            continue
        m = ORD.match(shape)
        order, kind, rest = int(m.group(1)), m.group(3), m.group(4).strip()
        span = None
        tag = rest.strip("()")
        if kind == "transverse" and tag in TENSIONER_SPANS:
            span = TENSIONER_SPANS[tag]
        out.append(dict(shape=shape, measured=meas, thesis=thesis, order=order, kind=kind, span=span,
                        table=table_id, span_tag=tag if tag in TENSIONER_SPANS else None))
    return out


def match_measured(rows: list[dict], labels: list[str], n_rigid: int) -> list[dict]:
    """Index (among the sorted flexible modes) of each measured mode, from the labels of the
    reference mesh: the lowest mode labelled '<order> <kind>' (on that span, if named)."""
    for row in rows:
        row["flex_index"] = None
        for i, lab in enumerate(labels):
            m = ORD.match(lab)
            if not m or int(m.group(1)) != row["order"] or m.group(3) != row["kind"]:
                continue
            if row["span"] is not None and not m.group(4).strip().startswith(row["span"]):
                continue
            row["flex_index"] = i - n_rigid
            row["label"] = lab
            break
    return rows


# --------------------------------------------------------------------------- errors


def rel_err(f, f_ref, k):
    """|f_i / f_ref_i - 1| of the first k flexible modes (inf where the mesh has fewer)."""
    e = np.full(k, np.inf)
    m = min(k, len(f), len(f_ref))
    e[:m] = np.abs(f[:m] / f_ref[:m] - 1.0)
    return e


def richardson(ns, fs, k):
    """Per mode: observed order p and extrapolated f* from three meshes n1 < n2 < n3 (h ~ 1/n)."""
    (n1, n2, n3), (f1, f2, f3) = ns, [np.asarray(f[:k]) for f in fs]
    h1, h2, h3 = 1.0 / n1, 1.0 / n2, 1.0 / n3
    p_out, fstar = np.full(k, np.nan), np.array(f3, float)
    for i in range(k):
        d12, d23 = f1[i] - f2[i], f2[i] - f3[i]
        if abs(d23) < 1e-13 * abs(f3[i]) or d12 * d23 <= 0:
            continue  # converged to round-off, or not monotone: keep the finest mesh
        r = d12 / d23
        lo, hi = 0.1, 20.0
        g = lambda p: (h1**p - h2**p) / (h2**p - h3**p) - r  # noqa: E731
        if g(lo) * g(hi) > 0:
            continue
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if g(lo) * g(mid) > 0 else (lo, mid)
        p = 0.5 * (lo + hi)
        C = d23 / (h2**p - h3**p)
        p_out[i], fstar[i] = p, f3[i] - C * h3**p
    return p_out, fstar


def needed(errs_by_n: dict, k: int, level: float, n_ref: int):
    """Fewest elements per span whose first-k error is within level, for that mesh and every finer
    one below the reference (None if no mesh coarser than the reference reaches it)."""
    ns = sorted(n for n in errs_by_n if n != n_ref)
    ok = [n for n in ns if all(np.max(errs_by_n[m][:k]) <= level for m in ns if m >= n)]
    return min(ok) if ok else None


# --------------------------------------------------------------------------- part 1: meshes


def part_mesh(quick: bool, ref: dict) -> dict:
    groups = {
        "two_pulley": dict(
            timed="two_pulley_T600", others=("two_pulley_T200", "two_pulley_T400"),
            meshes=(4, 8, 16, 24) if quick else (2, 4, 6, 8, 12, 16, 24, 32),
            campbell=(8, 16) if quick else (4, 8, 16)),
        "tensioner": dict(
            timed="tensioner_bench_stage2", others=(),
            meshes=(4, 8, 16) if quick else (2, 4, 8, 12, 16, 24),
            campbell=() if quick else (8,)),
    }
    res = {}
    for gname, g in groups.items():
        scenes = (g["timed"], *g["others"])
        recs = {s: {} for s in scenes}
        camp = {}
        for n in g["meshes"]:
            t0 = time.perf_counter()
            recs[g["timed"]][n] = drive_stats(g["timed"], n)
            for s in g["others"]:
                recs[s][n] = drive_stats(s, n, timed=False)
            r = recs[g["timed"]][n]
            msg = (f"  {g['timed']} n={n:2d} ({r['n_independent']} coords): statics {fmt_time(r['statics_time']['median_s'])}"
                   f" (compile {r['statics_compile']['total_s']:.1f} s), modal {fmt_time(r['modal_time']['median_s'])}"
                   f" (compile {r['modal_compile']['total_s']:.1f} s)")
            if n in g["campbell"]:
                camp[n] = campbell_stats(g["timed"], n)
                msg += f", Campbell {fmt_time(camp[n]['median_s'])} (compile {camp[n]['compile_s']:.1f} s)"
            log(msg + f"  [{time.perf_counter() - t0:.0f} s]")
        n_ref = max(g["meshes"])
        three = sorted(g["meshes"])[-3:]
        out = {}
        for s in scenes:
            fref = recs[s][n_ref]["flex"]
            k = min(K_MODES, len(fref))
            p, fstar = richardson(three, [recs[s][m]["flex"] for m in three], k)
            ref_err = np.abs(fref[:k] / fstar - 1.0)
            errs = {n: rel_err(recs[s][n]["flex"], fref, k) for n in g["meshes"]}
            lab = labels_of(recs[s][n_ref])
            rows = match_measured(measured_rows(ref, s), lab, recs[s][n_ref]["n_rigid"])
            meas = {}
            for n in g["meshes"]:
                fl = recs[s][n]["flex"]
                e = []
                for row in rows:
                    i = row["flex_index"]
                    e.append(abs(fl[i] / row["measured"] - 1.0) if i is not None and i < len(fl) else np.inf)
                e = np.array(e)
                clean = np.array([row["span_tag"] in (None, "T1") and row["kind"] == "transverse" for row in rows])
                meas[n] = dict(errors=e, max=float(np.max(e)), rms=float(np.sqrt(np.mean(e**2))),
                               max_clean=float(np.max(e[clean])) if clean.any() else None)
            out[s] = dict(
                reference_elements=n_ref, flex_ref_hz=fref[:k], labels_ref=lab[: k + recs[s][n_ref]["n_rigid"]],
                richardson_meshes=three, richardson_order=p, richardson_hz=fstar,
                reference_error_estimate=ref_err, errors=errs, measured_rows=rows, measured_errors=meas,
                needed={f"{lv:g}": {str(kk): needed(errs, kk, lv, n_ref) for kk in KS} for lv in LEVELS},
            )
        # Campbell errors against the finest Campbell mesh
        if camp:
            nc = max(camp)
            nr = recs[g["timed"]][nc]["n_rigid"]
            fc = camp[nc]["freqs"][:, nr:nr + 8]
            for n, c in camp.items():
                fn = c["freqs"][:, nr:nr + 8]
                c["max_err_first8_vs_finest"] = float(np.nanmax(np.abs(fn / fc - 1.0)))
                c["reference_elements"] = nc
        res[gname] = dict(timed=g["timed"], meshes=list(g["meshes"]), campbell_meshes=list(g["campbell"]),
                          records={s: {n: {k2: v for k2, v in recs[s][n].items() if not k2.startswith("_")}
                                       for n in g["meshes"]} for s in scenes},
                          campbell=camp, accuracy=out)
    return res


def mesh_tables(res: dict) -> list[str]:
    tables = []
    for gname, g in res.items():
        s0 = g["timed"]
        acc = g["accuracy"][s0]
        rows = []
        for n in g["meshes"]:
            r = g["records"][s0][n]
            e = acc["errors"][n]
            c = g["campbell"].get(n)
            me = acc["measured_errors"][n]
            rows.append([
                n, r["n_independent"], *[f"{np.max(e[:k]):.1e}" for k in KS],
                f"{100 * me['max']:.2f} %" if math.isfinite(me["max"]) else "n/a",
                fmt_time(r["statics_time"]["min_s"]), fmt_time(r["modal_time"]["min_s"]),
                fmt_time(c["min_s"]) if c else "-",
                f"{r['statics_compile']['total_s']:.1f} s", f"{r['modal_compile']['total_s']:.1f} s",
                f"{c['compile_s']:.1f} s" if c else "-",
                ("(ref.)" if c and n == c["reference_elements"] else f"{c['max_err_first8_vs_finest']:.1e}") if c else "-",
            ])
        refn = acc["reference_elements"]
        what = "Table 7.6 (9 transverse modes)" if gname == "two_pulley" else "Table 7.9 (15 modes)"
        t = table(["el./span", "coords", *[f"err first {k}" for k in KS], f"max err vs measured ({what})",
                   "statics", "modal", f"Campbell ({len(RPM)} speeds)", "statics compile", "modal compile",
                   "Campbell compile", "Campbell err first 8 (all speeds)"],
                  rows, f"(1) {s0}: max relative error of the first k flexible frequencies against {refn} "
                        f"el./span, and cost (run times after compilation, min of the samples; compile = trace + "
                        f"lower + XLA; Campbell compile = first call - later call)")
        tables.append(t)
    # elements needed
    rows = []
    for gname, g in res.items():
        for s, acc in g["accuracy"].items():
            row = [s]
            for lv in LEVELS:
                row.append(" / ".join(str(acc["needed"][f"{lv:g}"][str(k)] or f">{sorted(g['meshes'])[-2]}") for k in KS))
            rows.append(row)
    tables.append(table(["scene", *[f"err <= {100 * lv:g} %: first {'/'.join(map(str, KS))} modes" for lv in LEVELS]],
                        rows, "(1) Elements per span needed (error vs the finest mesh, for that mesh and every finer one)"))
    # one table per group (the mesh lists may differ)
    for gname, g in res.items():
        rows = []
        for s, acc in g["accuracy"].items():
            row = [s, len(acc["measured_rows"])]
            for n in g["meshes"]:
                me = acc["measured_errors"][n]
                row.append(f"{100 * me['max']:.2f} / {100 * me['rms']:.2f}" if math.isfinite(me["max"]) else "n/a")
            if acc["measured_errors"][g["meshes"][-1]]["max_clean"] is not None and gname == "tensioner":
                row[0] += " (T1 span only: " + " / ".join(
                    f"{100 * acc['measured_errors'][n]['max_clean']:.2f}"
                    if math.isfinite(acc["measured_errors"][n]["max_clean"]) else "n/a"
                    for n in g["meshes"]) + ")"
            rows.append(row)
        tables.append(table(["scene", "measured modes", *[f"{n} el." for n in g["meshes"]]], rows,
                            "(1) Against the bench measurements: max / rms |f / f_measured - 1| in % "
                            "(n/a: the mesh has fewer modes than the measured ones)"))
    # reference quality
    rows = []
    for gname, g in res.items():
        for s, acc in g["accuracy"].items():
            k8 = min(8, len(acc["reference_error_estimate"]))
            p = acc["richardson_order"][:k8]
            rows.append([s, acc["reference_elements"], "/".join(map(str, acc["richardson_meshes"])),
                         f"{np.nanmax(acc['reference_error_estimate'][:k8]):.1e}",
                         f"{np.nanmax(acc['reference_error_estimate']):.1e}",
                         f"{np.nanmin(p):.1f}-{np.nanmax(p):.1f}" if np.any(np.isfinite(p)) else "-"])
    tables.append(table(["scene", "reference el./span", "Richardson meshes", "ref. error est. (first 8)",
                         f"(first {K_MODES})", "observed order p (first 8)"], rows,
                        "(1) Quality of the reference: Richardson extrapolation f* from the three finest meshes"))
    return tables


# --------------------------------------------------------------------------- part 2: transients


def part_transient(quick: bool) -> dict:
    data = json.loads((HERE / "results" / "transient.json").read_text())
    cases = data["results"]["cases"]
    out = dict(source="results/transient.json", source_date=data["machine"]["date"],
               source_commit=data["machine"].get("git_commit"), cases={})
    for key, c in cases.items():
        runs = [r for r in c["runs"] if not (r["reference"] and r["error"] == 0.0)]
        out["cases"][key] = dict(label=c["label"], window_s=c["window_s"], reference=c["reference"], runs=runs)
    # spot check with the current code (cost per simulated second; errors on the quick windows)
    spot = []
    if not quick:
        picks = {"rot": [("dopri8", dict(rtol=1e-12, atol=1e-15, ref=True)), ("generalized_alpha", dict(dt=1e-4, rho=0.9)),
                         ("tsit5", dict(rtol=1e-6, atol=1e-9)), ("dopri8", dict(rtol=1e-9, atol=1e-12))],
                 # hybrid: the default solver only (its cost per simulated second; the errors are in transient.json)
                 "hyb": [("generalized_alpha", dict(dt=1e-4, rho=0.9)), ("generalized_alpha", dict(dt=5e-5, rho=0.9))]}
        for key, runs in picks.items():
            case = bt.Case(key, quick=True)
            ref_out = None
            for name, p in runs:
                rec, ys = case.run(name, p, guard_s=60.0)
                o = case.outputs(ys) if ys is not None else None
                err = None
                if p.get("ref"):
                    ref_out = o
                elif o is not None and ref_out is not None:
                    err = bt.errors(o, ref_out, case.out_dt)[3]
                old = next((r for r in cases[key]["runs"] if r["solver"] == name and r["dt_s"] == p.get("dt")
                            and r["rtol"] == p.get("rtol") and (r["rho_inf"] == p.get("rho"))), None)
                spot.append(dict(case=key, solver=name, setting=bt.fmt_setting(rec), window_s=case.window,
                                 reference=bool(p.get("ref")),
                                 s_per_s=rec["s_per_s"], compile_s=rec["compile_s"], error_1khz=err,
                                 json_s_per_s=old["s_per_s"] if old else None, status=rec["status"]))
                log(f"  spot {key} {bt.SHORT[name]} {bt.fmt_setting(rec)}: {rec['s_per_s'] or float('nan'):.3g} s/s "
                    f"(transient.json {old['s_per_s'] if old else float('nan'):.3g}), compile {rec['compile_s']:.1f} s, "
                    f"{rec['status']}")
    out["spot_check"] = spot
    return out


LEVELS_T = (5e-2, 1e-2, 1e-3)


def transient_tables(res: dict) -> list[str]:
    rows = []
    for key, c in res["cases"].items():
        row = [key, c["label"].split(",")[0] + f" ({c['window_s']:g} s window)"]
        for lv in LEVELS_T:
            ok = [r for r in c["runs"] if r["status"] == "ok" and r["error_1khz"] is not None and r["error_1khz"] <= lv]
            if ok:
                b = min(ok, key=lambda r: r["s_per_s"])
                row.append(f"{bt.SHORT[b['solver']]} {bt.fmt_setting(b)}: {b['s_per_s']:.3g} s ({b['error_1khz']:.1e})")
            else:
                row.append("none tried reaches it")
        rows.append(row)
    t1 = table(["case", "model", *[f"fastest with err < 1 kHz <= {100 * lv:g} %: setting, wall s per simulated s (err)"
                                   for lv in LEVELS_T]], rows,
               f"(2) Transient solvers: cheapest setting per accuracy level (from {res['source']}, run of "
               f"{res['source_date'][:16]}, commit {res['source_commit']})")
    rows = []
    for key, c in res["cases"].items():
        for r in c["runs"]:
            rows.append([key, bt.SHORT[r["solver"]], bt.fmt_setting(r),
                         f"{r['s_per_s']:.3g} s" if r["s_per_s"] else "-",
                         f"{r['error_1khz']:.1e}" if r["error_1khz"] is not None else "-",
                         "ok" if r["status"] == "ok" else r["status"][:48]])
    t2 = table(["case", "solver", "setting", "wall / simulated s", "err < 1 kHz", "status"], rows,
               "(2) Every run of results/transient.json (reference runs left out)")
    out = [t1, t2]
    if res["spot_check"]:
        rows = [[s["case"], bt.SHORT[s["solver"]], s["setting"], f"{s['window_s']:g} s",
                 f"{s['s_per_s']:.3g} s" if s["s_per_s"] else "-",
                 f"{s['json_s_per_s']:.3g} s" if s["json_s_per_s"] else "-",
                 f"{s['error_1khz']:.1e}" if s["error_1khz"] is not None else ("(reference)" if s["reference"] else "-"),
                 f"{s['compile_s']:.1f} s"] for s in res["spot_check"]]
        out.append(table(["case", "solver", "setting", "window", "wall / sim. s now", "in transient.json",
                          "err < 1 kHz (this window)", "compile"], rows,
                         "(2) Spot check with the current code (bench_transient.Case, quick windows)"))
    return out


# --------------------------------------------------------------------------- part 3: fidelity


def _freq_from_crossings(t, x):
    x = x - np.mean(x)
    s = np.sign(x)
    idx = np.nonzero(s[1:] * s[:-1] < 0)[0]
    if len(idx) < 3:
        return float("nan")
    tc = t[idx] - x[idx] * (t[idx + 1] - t[idx]) / (x[idx + 1] - x[idx])
    return float((len(tc) - 1) / (2.0 * (tc[-1] - tc[0])))


def part_fidelity(quick: bool) -> dict:
    out = dict(statics_modal=[], transient={})
    cases = [("two_pulley_T600", 16, False), ("tensioner_bench_stage2", 8, False)]
    if not quick:
        cases.append(("two_pulley_T600", 16, True))
    for base, n, driven in cases:
        pair = {}
        for fid in ("ancf", "rotational"):
            rec = drive_stats(base, n, fid, driven)
            lab = labels_of(rec)
            rot = [(float(f), l) for f, l in zip(rec["freqs"], lab) if "rotational" in l]
            pair[fid] = dict(n_independent=rec["n_independent"], tensions=rec["tensions"],
                             hub=rec["hubs"][1] if base.startswith("two") else rec["hubs"][2],
                             theta_deg=rec["theta_deg"], rotational_modes=rot,
                             statics_s=rec["statics_time"]["median_s"], modal_s=rec["modal_time"]["median_s"],
                             statics_compile_s=rec["statics_compile"]["total_s"],
                             modal_compile_s=rec["modal_compile"]["total_s"])
        out["statics_modal"].append(dict(scene=base, elements=n, crank_driven=driven, **pair))
        log(f"  {base}{' crank driven' if driven else ''}: rot modes {pair['rotational']['rotational_modes'][:2]} "
            f"hyb {pair['ancf']['rotational_modes'][:2]}")
    # transient: thesis Simulation 1 (alternator released from 2 deg, belt damping), both fidelities
    txt = (ROOT / "scenes" / "sim_two_pulley_release.toml").read_text()
    window = 0.05 if quick else 0.1
    runs = {}
    for fid in ("rotational", "ancf"):
        t = txt
        if fid == "ancf":
            t = t.replace('fidelity = "rotational"', 'fidelity = "ancf"\nelements_per_span = 16')
        sc = dataclasses.replace(drive.canonical(loads_scene(t)), simulation=Simulation())  # default solver
        t0 = time.perf_counter()
        transient.simulate(sc, window, output_dt=1e-4)
        first = time.perf_counter() - t0
        walls = []
        for _ in range(1 if fid == "ancf" else 3):
            t0 = time.perf_counter()
            r = transient.simulate(sc, window, output_dt=1e-4)
            walls.append(time.perf_counter() - t0)
        wall = min(walls)
        ch = r.channels
        alt = r.columns["pulley_speeds_rpm"].index("alternator")
        runs[fid] = dict(n_independent=r.meta["n_independent"], first_call_s=first, wall_s=wall, walls_s=walls,
                         s_per_s=wall / window, steps=r.meta["steps"], t=r.t,
                         tension=ch["span_tensions_N"], speed_alt=ch["pulley_speeds_rpm"][:, alt],
                         hub_alt=ch["hub_force_magnitudes_N"][:, alt],
                         freq_hz=_freq_from_crossings(r.t, ch["pulley_speeds_rpm"][:, alt]))
        log(f"  transient {fid}: {wall / window:.3g} s/s (first call {first:.1f} s), torsional {runs[fid]['freq_hz']:.2f} Hz")
    a, b = runs["ancf"], runs["rotational"]

    def rel(x, y):
        return float(np.max(np.abs(x - y)) / max(np.ptp(y), 1e-300))

    out["transient"] = dict(
        scene="scenes/sim_two_pulley_release.toml (alternator +2 deg, CA = 3.33 N s), each model's default solver "
              "(hybrid: generalized-alpha dt 1e-4 s rho_inf 0.9; rotational: Dopri8 rtol 1e-6), outputs every 1e-4 s", window_s=window,
        runs={k: {kk: vv for kk, vv in v.items() if kk not in ("t", "tension", "speed_alt", "hub_alt")} for k, v in runs.items()},
        tension_t0=dict(rotational=b["tension"][0], ancf=a["tension"][0]),
        diff_tension_rel_range=rel(a["tension"], b["tension"]),
        diff_speed_rel_range=rel(a["speed_alt"], b["speed_alt"]),
        peak_to_peak_tension=dict(rotational=np.ptp(b["tension"], axis=0), ancf=np.ptp(a["tension"], axis=0)),
        peak_to_peak_speed=dict(rotational=float(np.ptp(b["speed_alt"])), ancf=float(np.ptp(a["speed_alt"]))),
    )
    out["_series"] = runs
    return out


def fidelity_tables(res: dict) -> list[str]:
    rows = []
    for c in res["statics_modal"]:
        a, b = c["ancf"], c["rotational"]
        name = c["scene"] + (" (crank driven)" if c["crank_driven"] else "")
        dT = np.max(np.abs(a["tensions"] / b["tensions"] - 1))
        dH = np.linalg.norm(a["hub"] - b["hub"]) / np.linalg.norm(b["hub"])
        fr_a = ", ".join(f"{f:.2f}" for f, _ in a["rotational_modes"][:2])
        fr_b = ", ".join(f"{f:.2f}" for f, _ in b["rotational_modes"][:2])
        d_f = ", ".join(f"{100 * (fa / fb - 1):+.2f} %" for (fa, _), (fb, _) in
                        zip(a["rotational_modes"][:2], b["rotational_modes"][:2]))
        arm = (f"{a['theta_deg']:.3f} / {b['theta_deg']:.3f}" if a["theta_deg"] is not None else "-")
        rows.append([name, f"{c['elements']} el.: {a['n_independent']} / {b['n_independent']}",
                     " ".join(f"{x:.2f}" for x in a["tensions"]), f"{dT:.1e}", f"{dH:.1e}", arm,
                     f"{fr_a} / {fr_b}", d_f,
                     f"{fmt_time(a['statics_s'])} / {fmt_time(b['statics_s'])}",
                     f"{fmt_time(a['modal_s'])} / {fmt_time(b['modal_s'])}",
                     f"{a['statics_compile_s'] + a['modal_compile_s']:.1f} s / {b['statics_compile_s'] + b['modal_compile_s']:.1f} s"])
    t1 = table(["scene", "coords hyb / rot", "span tensions hyb (N)", "max rel. diff tensions", "rel. diff hub force",
                "arm angle hyb / rot (deg)", "rotational modes hyb / rot (Hz)", "hyb vs rot", "statics hyb / rot",
                "modal hyb / rot", "compile (statics + modal) hyb / rot"], rows,
               "(3) Hybrid (ANCF) vs rotational fidelity, same scene: statics and rotational modes (at rest)")
    tr = res["transient"]
    rows = []
    for fid in ("ancf", "rotational"):
        r = tr["runs"][fid]
        rows.append([{"ancf": "hybrid, 16 el./span", "rotational": "rotational"}[fid], r["n_independent"],
                     " / ".join(f"{x:.1f}" for x in tr["tension_t0"][fid]),
                     " / ".join(f"{x:.1f}" for x in tr["peak_to_peak_tension"][fid]),
                     f"{tr['peak_to_peak_speed'][fid]:.1f}", f"{r['freq_hz']:.2f}", f"{r['s_per_s']:.3g} s",
                     f"{r['first_call_s']:.1f} s"])
    t2 = table(["model", "unknowns", "span tensions at t = 0 (N)", "peak-peak tensions (N)",
                "peak-peak alternator speed (rpm)", "torsional freq. (zero crossings, Hz)", "wall / simulated s",
                "first call (compile + run)"], rows,
               f"(3) Transient, {tr['scene']}, {tr['window_s']:g} s: max |hyb - rot| / range(rot) = "
               f"{tr['diff_tension_rel_range']:.2f} (span tension), {tr['diff_speed_rel_range']:.2f} (alternator speed)")
    return [t1, t2]


# --------------------------------------------------------------------------- part 4: effects


def _count_eqns(jaxpr) -> int:
    n = 0
    for eq in jaxpr.eqns:
        n += 1
        for v in eq.params.values():
            for sub in (v if isinstance(v, (list, tuple)) else [v]):
                if hasattr(sub, "eqns"):
                    n += _count_eqns(sub)
                elif hasattr(sub, "jaxpr") and hasattr(sub.jaxpr, "eqns"):
                    n += _count_eqns(sub.jaxpr)
    return n


def _vf(scene, inst, t, y):
    return transient.vector_field(scene, inst)(t, y, None)


_vf_jit = jax.jit(_vf)


def _f64(x):
    """A float64 array that is not weak-typed, like the scene parser's leaves (a weak-typed leaf,
    e.g. set with jnp.asarray(2.0), changes the abstract value and forces a new compilation)."""
    return jnp.asarray(np.asarray(x, dtype=np.float64))


def _set_params(sc, effect):
    """The scene with the parameters of ``effect`` set (effect listed or not: the model decides)."""
    if effect == "belt_damping":
        return eqx.tree_at(lambda s: s.belt.CA, sc, _f64(2.0))
    if effect == "bearing_damping":
        return eqx.tree_at(lambda s: s.pulleys[1].bearing_damping, sc, _f64(1e-3))
    if effect == "unbalance":
        return eqx.tree_at(lambda s: s.pulleys[1].cm_offset, sc, _f64([1e-4, 0.0]))
    if effect == "speed_fluctuation":
        return eqx.tree_at(lambda s: (s.pulleys[0].fluctuation_amplitude_deg, s.pulleys[0].fluctuation_frequency_hz),
                           sc, (_f64(1.0), _f64(20.0)))
    if effect == "tensioner_damping":
        return eqx.tree_at(lambda s: s.tensioner.damping, sc, _f64(0.1))
    return sc  # transport, gravity: no parameter


def _with_effects(sc, effects):
    sc = dataclasses.replace(sc, model=dataclasses.replace(sc.model, effects=tuple(effects)))
    for e in effects:
        sc = _set_params(sc, e)
    return sc


def _hlo_ops(text: str) -> int:
    return sum(1 for line in text.splitlines() if re.match(r"^\s*(%\S+|\S+)\s*=\s*\S", line) and "ENTRY" not in line)


def _effect_series(base_sc, effects_list, label, y_seed):
    """Compile / size / run time of the vector field for each effect set; 'absent' checks."""
    qi, inst, _ = jax.jit(lambda s: statics.equilibrium(s, speed=drive.belt_speed(s)))(base_sc)
    rng = np.random.default_rng(y_seed)
    n = drive.n_independent(base_sc)
    y = jnp.concatenate([qi + 1e-5 * jnp.asarray(rng.standard_normal(n)), 1e-3 * jnp.asarray(rng.standard_normal(n))])
    t = jnp.asarray(0.0123)
    variants = {"none": []}
    for e in effects_list:
        variants[f"+{e}"] = [e]
    if len(effects_list) > 1:
        variants["all"] = list(effects_list)
    rows, calls = {}, {}
    _vf_jit.lower(_with_effects(base_sc, list(effects_list)), inst, t, y).compile()  # warm-up (discarded)
    for name, effs in variants.items():
        sc = _with_effects(base_sc, effs)
        jx = jax.make_jaxpr(_vf)(sc, inst, t, y)
        js = jax.make_jaxpr(lambda q, s: drive.static_residual(q, s, inst, drive.belt_speed(s)))(qi, sc)
        jax.clear_caches()  # every variant compiles cold
        t0 = time.perf_counter()
        lowered = _vf_jit.lower(sc, inst, t, y)
        t1 = time.perf_counter()
        compiled = lowered.compile()
        t2 = time.perf_counter()
        cost = compiled.cost_analysis() or {}
        if isinstance(cost, list):
            cost = cost[0] if cost else {}
        f = np.asarray(compiled(sc, inst, t, y))
        rows[name] = dict(effects=effs, jaxpr_eqns=_count_eqns(jx.jaxpr), jaxpr_text=str(jx),
                          static_residual_eqns=_count_eqns(js.jaxpr),
                          stablehlo_ops=_hlo_ops(lowered.as_text()), hlo_instructions=_hlo_ops(compiled.as_text()),
                          flops=cost.get("flops"), lower_s=t1 - t0, compile_s=t2 - t1, f=f)
        calls[name] = (lambda sc=sc, c=compiled: c(sc, inst, t, y))  # the AOT executable (caches are cleared)
        log(f"  {label} {name:20s} eqns {rows[name]['jaxpr_eqns']:6d}  hlo {rows[name]['hlo_instructions']:6d}  "
            f"compile {t2 - t0:.1f} s")
    times = time_interleaved(calls, rounds=41, max_total_s=12.0)
    for name in rows:
        rows[name]["time"] = times[name]
    # absent: parameters set, effect not listed
    absent = {}
    base_row = rows["none"]
    sc_none = _with_effects(base_sc, [])
    jax.block_until_ready(_vf_jit(sc_none, inst, t, y))  # the jit cache now holds the scene without effects
    for e in effects_list:
        sc = _set_params(_with_effects(base_sc, []), e)
        jx = jax.make_jaxpr(_vf)(sc, inst, t, y)
        c0 = _vf_jit._cache_size()
        f = np.asarray(_vf_jit(sc, inst, t, y))
        tm = time_interleaved({"absent": lambda sc=sc: _vf_jit(sc, inst, t, y),
                               "none": lambda: _vf_jit(sc_none, inst, t, y)},
                              rounds=21, max_total_s=3.0)
        absent[e] = dict(parameters_set=e not in ("transport", "gravity"),
                         jaxpr_identical=str(jx) == base_row["jaxpr_text"], jaxpr_eqns=_count_eqns(jx.jaxpr),
                         new_cache_entries=_vf_jit._cache_size() - c0,
                         max_abs_diff_f=float(np.max(np.abs(f - base_row["f"]))),
                         time_ratio_vs_none=tm["absent"]["min_s"] / tm["none"]["min_s"])
    for r in rows.values():
        r.pop("jaxpr_text")
        r.pop("f")
    return dict(label=label, n_independent=n, variants=rows, absent=absent, _scene=base_sc, _inst=inst, _y=y)


def _short_transient(base_sc, inst, y0, effects, window=0.02):
    """wall s per simulated s of generalized-alpha (dt 1e-4, rho 0.9) via bench_transient._chunk."""
    sc = _with_effects(base_sc, effects)
    per = 50
    args = (jnp.asarray(1e-4), jnp.asarray(1e-6), jnp.asarray(1e-9), jnp.asarray(0.9))
    ms = per + 16
    ts0 = jnp.linspace(0.0, 4e-4, per + 1)
    t0 = time.perf_counter()
    states = bt._start(sc, inst, y0, *args, "generalized_alpha")
    jax.block_until_ready(bt._chunk(sc, inst, y0, ts0, *args, "generalized_alpha", ms, states))
    compile_s = time.perf_counter() - t0
    y = y0
    nch = int(round(window / (per * 1e-4)))
    t0 = time.perf_counter()
    steps = 0
    states = bt._start(sc, inst, y0, *args, "generalized_alpha")
    for c in range(nch):
        ts = jnp.asarray((c * per + np.arange(per + 1)) * 1e-4)
        ys, code, nst, _, states = bt._chunk(sc, inst, y, ts, *args, "generalized_alpha", ms, states)
        assert int(code) == 0, (effects, int(code))
        y = ys[-1]
        steps += int(nst)
    jax.block_until_ready(y)
    wall = time.perf_counter() - t0
    return dict(effects=list(effects), compile_s=compile_s, wall_s=wall, window_s=window, s_per_s=wall / window,
                steps=steps)


def part_effects(quick: bool) -> dict:
    two = drive.canonical(bt.make_scene(base="two_pulley_T600", driven_rpm=600, effects=[]))
    effs = ["transport", "belt_damping", "gravity", "bearing_damping", "unbalance", "speed_fluctuation"]
    out = dict(two_pulley=_effect_series(two, effs, "two-pulley 16 el.", 0))
    if not quick:
        tens = drive.canonical(bt.make_scene(base="tensioner_bench_stage2", driven_rpm=600, effects=[]))
        out["tensioner"] = _effect_series(tens, ["tensioner_damping"], "tensioner 8 el.", 1)
        s = out["two_pulley"]
        out["short_transient"] = []
        qi0 = s["_y"][: s["n_independent"]]
        y0 = jnp.concatenate([qi0, jnp.zeros_like(qi0)])
        for e in ([], effs):
            r = _short_transient(s["_scene"], s["_inst"], y0, e)
            out["short_transient"].append(r)
            log(f"  GA transient {('+'.join(e) or 'none'):70s}: {r['s_per_s']:.3g} s/s (compile {r['compile_s']:.1f} s)")
    return out


def effects_tables(res: dict) -> list[str]:
    out = []
    for key in ("two_pulley", "tensioner"):
        if key not in res:
            continue
        s = res[key]
        base = s["variants"]["none"]
        rows = []
        for name, r in s["variants"].items():
            rows.append([name, r["jaxpr_eqns"], f"{r['jaxpr_eqns'] - base['jaxpr_eqns']:+d}", r["static_residual_eqns"],
                         r["stablehlo_ops"], r["hlo_instructions"],
                         f"{r['flops']:.4g}" if r["flops"] else "-", f"{r['lower_s'] + r['compile_s']:.2f} s",
                         f"{fmt_time(r['time']['median_s'])} ({fmt_time(r['time']['min_s'])})",
                         f"{r['time']['median_s'] / base['time']['median_s']:.2f}x"])
        out.append(table(["effects", "jaxpr eqns (vector field)", "vs none", "jaxpr eqns (static residual)",
                          "StableHLO ops", "HLO instr. (optimised)", "XLA flops", "compile", "run time / call, median (min)",
                          "vs none"], rows,
                         f"(4) Effects vs compiled size and cost: transient right-hand side of the {s['label']} drive "
                         f"({s['n_independent']} unknowns), crank driven at 600 rpm"))
        rows = [[e, "yes" if a["parameters_set"] else "(no parameter)", "identical" if a["jaxpr_identical"] else "DIFFERENT",
                 a["jaxpr_eqns"], a["new_cache_entries"], f"{a['max_abs_diff_f']:.1e}", f"{a['time_ratio_vs_none']:.2f}x"]
                for e, a in s["absent"].items()]
        out.append(table(["effect not listed", "its parameters set", "jaxpr vs none", "jaxpr eqns",
                          "new compilations", "max abs(f - f_none)", "run time vs none (min/min)"], rows,
                         f"(4) An effect not listed costs nothing ({s['label']})"))
    if res.get("short_transient"):
        base = res["short_transient"][0]["s_per_s"]
        rows = [["+".join(r["effects"]) or "none", r["steps"], f"{r['s_per_s']:.3g} s", f"{r['s_per_s'] / base:.2f}x",
                 f"{r['compile_s']:.1f} s"] for r in res["short_transient"]]
        out.append(table(["effects", "steps", "wall / simulated s", "vs none", "compile (first chunk)"], rows,
                         "(4) Generalized-alpha (dt 1e-4 s, rho_inf 0.9) on the two-pulley drive, 0.02 s"))
    return out


# --------------------------------------------------------------------------- figures


def _plain_x(ax, ticks=None):
    """Plain numbers on a log x axis (no 10^x labels crowding each other)."""
    if ticks is not None:
        ax.set_xticks(ticks)
    else:
        ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())


def _save(fig, name: str):
    """Lay out, write figures/<name> (110 dpi) and close ``fig``; returns the path."""
    fig.tight_layout()
    path = FIGURES / name
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def figures(mesh, trans, fid, eff):
    FIGURES.mkdir(parents=True, exist_ok=True)
    paths = []
    colors = {"two_pulley_T200": "tab:blue", "two_pulley_T400": "tab:cyan", "two_pulley_T600": "tab:green",
              "tensioner_bench_stage2": "tab:red"}
    if mesh:
        fig, axs = plt.subplots(1, 3, figsize=(17, 5.2))
        for gname, g in mesh.items():
            for s, acc in g["accuracy"].items():
                ns = [n for n in g["meshes"] if n != acc["reference_elements"]]
                for k, ls in ((8, "-"), (4, ":"), (16, "--")):
                    e = [np.max(acc["errors"][n][:k]) for n in ns]
                    axs[0].loglog(ns, e, ls, marker="o", color=colors[s], ms=4,
                                  label=f"{s}, first {k}" if k == 8 or s in ("two_pulley_T600", "tensioner_bench_stage2") else None)
                me = [acc["measured_errors"][n]["max"] for n in g["meshes"]]
                axs[2].semilogy(g["meshes"], me, "-o", color=colors[s], ms=4, label=f"{s} (all measured)")
                if gname == "tensioner":
                    mc = [acc["measured_errors"][n]["max_clean"] for n in g["meshes"]]
                    axs[2].semilogy(g["meshes"], mc, "--s", color=colors[s], ms=4, label=f"{s} (span T1 only)")
            s0 = g["timed"]
            acc = g["accuracy"][s0]
            ns = [n for n in g["meshes"] if n != acc["reference_elements"]]
            tt = [g["records"][s0][n]["statics_time"]["min_s"] + g["records"][s0][n]["modal_time"]["min_s"] for n in ns]
            e8 = [np.max(acc["errors"][n][:8]) for n in ns]
            axs[1].loglog(tt, e8, "-o", color=colors[s0], label=f"{s0}: statics + modal")
            for n, x, yv in zip(ns, tt, e8):
                axs[1].annotate(f"{n}", (x, yv), textcoords="offset points", xytext=(4, 4), fontsize=8, color=colors[s0])
            cm = [n for n in g["campbell_meshes"] if n != max(g["campbell_meshes"]) and n in acc["errors"]]
            if cm:
                axs[1].loglog([g["campbell"][n]["median_s"] for n in cm], [np.max(acc["errors"][n][:8]) for n in cm],
                              "--^", color=colors[s0], label=f"{s0}: Campbell, {len(RPM)} speeds")
        for a in axs[:2]:
            a.axhline(1e-2, color="grey", lw=0.8, ls="--")
            a.axhline(1e-3, color="grey", lw=0.8, ls=":")
        axs[2].axhline(1e-2, color="grey", lw=0.8, ls="--")
        allm = sorted({n for g in mesh.values() for n in g["meshes"]})
        _plain_x(axs[0], allm)
        axs[2].set_xscale("log")
        _plain_x(axs[2], allm)
        _plain_x(axs[1])
        axs[0].set_xlabel("elements per span")
        axs[0].set_ylabel("max relative error vs finest mesh")
        axs[0].set_title("frequency error of the first k flexible modes\n(solid: k = 8, dotted: 4, dashed: 16)")
        axs[1].set_xlabel("time after compilation (s)")
        axs[1].set_ylabel("max rel. error, first 8 flexible modes")
        axs[1].set_title("accuracy vs time (labels: elements per span)")
        axs[2].set_xlabel("elements per span")
        axs[2].set_ylabel("max |f / f_measured - 1|")
        axs[2].set_title("against the bench measurements (Tables 7.2-7.9)")
        for a in axs:
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=7)
        paths.append(_save(fig, "atlas_mesh.png"))
        # costs
        fig, axs = plt.subplots(1, 2, figsize=(12, 4.8))
        for gname, g in mesh.items():
            s0 = g["timed"]
            ns = g["meshes"]
            R = g["records"][s0]
            c = colors[s0]
            axs[0].loglog(ns, [R[n]["statics_time"]["min_s"] for n in ns], "-o", color=c, label=f"{s0}: statics")
            axs[0].loglog(ns, [R[n]["modal_time"]["min_s"] for n in ns], "--s", color=c, label=f"{s0}: modal")
            if g["campbell"]:
                cm = sorted(g["campbell"])
                axs[0].loglog(cm, [g["campbell"][n]["median_s"] for n in cm], ":^", color=c,
                              label=f"{s0}: Campbell ({len(RPM)} speeds)")
            axs[1].semilogx(ns, [R[n]["statics_compile"]["total_s"] for n in ns], "-o", color=c, label=f"{s0}: statics")
            axs[1].semilogx(ns, [R[n]["modal_compile"]["total_s"] for n in ns], "--s", color=c, label=f"{s0}: modal")
            if g["campbell"]:
                axs[1].semilogx(cm, [g["campbell"][n]["compile_s"] for n in cm], ":^", color=c, label=f"{s0}: Campbell")
        allm = sorted({n for g in mesh.values() for n in g["meshes"]})
        for a in axs:
            _plain_x(a, allm)
        axs[0].set_title("run time after compilation (min of the samples)")
        axs[0].legend(fontsize=7, loc="upper left")
        axs[1].set_title("compile time (shared machine: noisy)")
        for a in axs:
            a.set_xlabel("elements per span")
            a.set_ylabel("s")
            a.grid(True, which="both", alpha=0.3)
        axs[0].legend(fontsize=7, loc="upper left")
        axs[1].legend(fontsize=7)
        paths.append(_save(fig, "atlas_mesh_cost.png"))
    if trans:
        keys = list(trans["cases"])
        fig, axs = plt.subplots(1, len(keys), figsize=(4.6 * len(keys), 4.6))
        axs = np.atleast_1d(axs)
        mk = {"generalized_alpha": "o", "tsit5": "s", "dopri8": "^", "kvaerno5": "D"}
        for a, key in zip(axs, keys):
            c = trans["cases"][key]
            for solver in mk:
                rs = [r for r in c["runs"] if r["solver"] == solver and r["status"] == "ok" and r["error_1khz"]
                      and not r["reference"]]
                if solver == "generalized_alpha":
                    for rho, ls in ((0.9, "-"), (1.0, ":")):
                        rr = sorted([r for r in rs if r["rho_inf"] == rho], key=lambda r: r["s_per_s"])
                        if rr:
                            a.loglog([r["s_per_s"] for r in rr], [r["error_1khz"] for r in rr], ls + mk[solver],
                                     label=f"gen-alpha rho {rho:g}")
                            for r in rr:
                                a.annotate(f"{r['dt_s']:g}", (r["s_per_s"], r["error_1khz"]), fontsize=7,
                                           textcoords="offset points", xytext=(3, 3))
                    continue
                rs = sorted(rs, key=lambda r: r["s_per_s"])
                if rs:
                    a.loglog([r["s_per_s"] for r in rs], [r["error_1khz"] for r in rs], "-" + mk[solver],
                             label=bt.SHORT[solver])
                    for r in rs:
                        a.annotate(f"{r['rtol']:g}", (r["s_per_s"], r["error_1khz"]), fontsize=7,
                                   textcoords="offset points", xytext=(3, -9))
            a.axhline(1e-2, color="grey", lw=0.8, ls="--")
            a.set_title(f"({key}) {c['window_s']:g} s window", fontsize=10)
            a.set_xlabel("wall s per simulated s")
            _plain_x(a)
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=7)
        axs[0].set_ylabel("max rel. error of the response < 1 kHz")
        fig.suptitle("Transient solvers: error vs cost (labels: dt or rtol); from results/transient.json", fontsize=10)
        paths.append(_save(fig, "atlas_transient.png"))
    if fid and "_series" in fid:
        S = fid["_series"]
        fig, axs = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
        for fidn, ls, lab in (("rotational", "-", "rotational"), ("ancf", "--", "hybrid 16 el./span")):
            r = S[fidn]
            axs[0].plot(1e3 * r["t"], r["speed_alt"], ls, label=f"{lab} ({r['freq_hz']:.2f} Hz)")
            axs[1].plot(1e3 * r["t"], r["tension"][:, 0], ls, label=f"{lab}, span 1")
            axs[1].plot(1e3 * r["t"], r["tension"][:, 1], ls, label=f"{lab}, span 2")
        axs[0].set_ylabel("alternator speed (rpm)")
        axs[1].set_ylabel("span tension (N)")
        axs[1].set_xlabel("t (ms)")
        axs[0].set_title("Thesis Simulation 1 (alternator released from 2 deg, CA = 3.33 N s): both fidelities")
        for a in axs:
            a.grid(alpha=0.3)
            a.legend(fontsize=8)
        paths.append(_save(fig, "atlas_fidelity.png"))
    if eff:
        s = eff["two_pulley"]
        names = list(s["variants"])
        fig, axs = plt.subplots(1, 3, figsize=(15, 4.5))
        v = s["variants"]
        axs[0].barh(names, [v[n]["jaxpr_eqns"] for n in names], color="tab:blue")
        axs[0].set_xlabel("jaxpr equations of the vector field")
        axs[1].barh(names, [v[n]["lower_s"] + v[n]["compile_s"] for n in names], color="tab:orange")
        axs[1].set_xlabel("compile time (s)")
        axs[2].barh(names, [1e6 * v[n]["time"]["median_s"] for n in names], color="tab:green")
        axs[2].set_xlabel("run time per call (us)")
        for a in axs:
            a.invert_yaxis()
            a.grid(axis="x", alpha=0.3)
        fig.suptitle(f"Effects: transient right-hand side of the {s['label']} drive (a listed effect costs; "
                     "an unlisted one is not traced)", fontsize=10)
        paths.append(_save(fig, "atlas_effects.png"))
    return paths


# --------------------------------------------------------------------------- main


def _from_json(x):
    """results/atlas.json back to what figures() reads: integer mesh keys, None (inf/nan) -> inf."""
    if isinstance(x, dict):
        return {(int(k) if isinstance(k, str) and k.isdigit() else k): _from_json(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_from_json(v) for v in x]
    return np.inf if x is None else x


def _strip(x):
    if isinstance(x, dict):
        return {k: _strip(v) for k, v in x.items() if not str(k).startswith("_")}
    if isinstance(x, (list, tuple)):
        return [_strip(v) for v in x]
    return x


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer meshes and cases (about 4 min)")
    ap.add_argument("--parts", nargs="*", default=["mesh", "transient", "fidelity", "effects"],
                    help="subset of: mesh transient fidelity effects")
    ap.add_argument("--replot", action="store_true",
                    help="only redraw the figures from results/atlas.json (the transient time series of part 3 "
                         "are not stored: atlas_fidelity.png is kept)")
    ns = ap.parse_args()
    if ns.replot:
        r = _from_json(json.loads((HERE / "results" / "atlas.json").read_text())["results"])
        for p in figures(r.get("mesh"), r.get("transient"), None, r.get("effects")):
            log(f"redrew {p}")
        return
    t_all = time.perf_counter()
    info = machine_info()
    log(machine_line(info))
    ref = json.loads(REFERENCE.read_text())
    # warm-up: the first XLA compilation of a process carries one-time costs; keep them out of the tables
    jax.block_until_ready(jax.jit(lambda a: jnp.linalg.eigh(a @ a.T + jnp.eye(4))[0] + jnp.linalg.solve(a, a[0]))(
        jnp.arange(16.0).reshape(4, 4) + jnp.eye(4)))
    tables, results, elapsed = [], dict(quick=ns.quick), {}
    try:  # read-only: which library files differ from the commit (the tree may hold others' uncommitted work)
        import subprocess

        results["working_tree_changes"] = subprocess.run(
            ["git", "status", "--porcelain", "--", "beltjax", "benchmarks/bench_transient.py", "benchmarks/_common.py"],
            cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.splitlines()
    except Exception:  # noqa: BLE001
        results["working_tree_changes"] = None
    log(f"library files changed vs the commit: {results['working_tree_changes']}")
    parts = {  # name: (heading, run, tables)
        "mesh": ("(1) elements per span on the whole drives", lambda: part_mesh(ns.quick, ref), mesh_tables),
        "transient": ("(2) transient solvers (results/transient.json, spot check)",
                      lambda: part_transient(ns.quick), transient_tables),
        "fidelity": ("(3) rotational vs hybrid", lambda: part_fidelity(ns.quick), fidelity_tables),
        "effects": ("(4) effects vs compiled cost", lambda: part_effects(ns.quick), effects_tables),
    }
    for name, (heading, run, make_tables) in parts.items():
        if name not in ns.parts:
            continue
        log(f"== {heading}")
        t0 = time.perf_counter()
        results[name] = run()
        elapsed[name] = time.perf_counter() - t0
        for t in make_tables(results[name]):
            log(t + "\n")
            tables.append(t)
    mesh, trans, fid, eff = (results.get(k) for k in ("mesh", "transient", "fidelity", "effects"))
    paths = figures(mesh, trans, fid, eff)
    elapsed["total"] = time.perf_counter() - t_all
    results["elapsed_s"] = elapsed
    results["figures"] = [str(p.relative_to(HERE)) for p in paths]
    path = save_json("atlas", dict(results=_strip(results), tables=tables))
    log(f"figures: {', '.join(results['figures'])}")
    log(f"wrote {path}; elapsed " + ", ".join(f"{k} {v:.0f} s" for k, v in elapsed.items()))


if __name__ == "__main__":
    main()
