"""A sweep's result as tables: output columns, statistics, failures, sweep.csv, sweep_campbell.csv and
sweep.json."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from beltjax import drive, friction
from beltjax.scene import Scene
from beltjax.sweep.spec import REASONS, STATUS, Spec, _CODE, nominal_value


def columns(scene: Scene, result: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-case output columns of :func:`evaluate`'s result, tidy: ``tension_<span>_N``,
    ``hub_<entry>_N``, ``installation_tension_N``, ``belt_length_m``, ``tensioner_angle_deg``,
    ``spring_moment_Nm``, ``converged``, ``f<k>_hz`` (the nominal scene's k-th mode, followed
    by its shape: see :func:`evaluate`), ``mode_match`` (the lowest MAC of a case's columns
    with the nominal's modes, 0 where one is not found), ``stable``,
    ``campbell_unstable_from_rpm``, ``campbell_mode_match``."""
    cols: dict[str, np.ndarray] = {}
    if "span_tensions_N" in result:
        for j, name in enumerate(drive.span_names(scene)):
            cols[f"tension_{name}_N"] = result["span_tensions_N"][:, j]
        for j, name in enumerate(scene.route.order):
            cols[f"hub_{name}_N"] = result["hub_forces_N"][:, j]
        for k in ("installation_tension_N", "belt_length_m", "tensioner_angle_deg", "spring_moment_Nm", "converged",
                  "drive_torque_Nm"):
            if k in result:
                cols[k] = result[k]
        if "friction_needed" in result:  # the operating point's arcs (capstan law)
            given = friction.given(scene)
            for j, name in enumerate(scene.route.order):
                cols[f"friction_needed_{name}"] = result["friction_needed"][:, j]
                if j in given:
                    cols[f"slip_margin_{name}"] = result["slip_margins"][:, given.index(j)]
            if given:
                cols["min_slip_margin"] = np.min(result["slip_margins"], axis=1)
    if "response_span_p2p_N" in result:  # the periodic steady state at the case's speed
        if "response_arm_p2p_deg" in result:
            cols["arm_p2p_deg"] = result["response_arm_p2p_deg"]
        for j, name in enumerate(drive.span_names(scene)):
            cols[f"tension_p2p_{name}_N"] = result["response_span_p2p_N"][:, j]
            cols[f"tension_min_{name}_N"] = result["response_span_min_N"][:, j]
        bearings = list(scene.route.order) + (["tensioner pivot"] if scene.tensioner is not None else [])
        for j, name in enumerate(bearings):
            cols[f"hub_max_{name.replace(' ', '_')}_N"] = result["response_hub_max_N"][:, j]
        if "response_min_slip_margin" in result:
            cols["dynamic_min_slip_margin"] = np.min(result["response_min_slip_margin"], axis=1)
    if "frequencies_hz" in result:
        for m in range(result["frequencies_hz"].shape[1]):
            cols[f"f{m + 1}_hz"] = result["frequencies_hz"][:, m]
        if "mode_mac" in result:
            mac = result["mode_mac"]
            cols["mode_match"] = np.where(np.isfinite(mac).any(axis=1),
                                          np.min(np.where(np.isfinite(mac), mac, 0.0), axis=1), np.nan)
        cols["stable"] = result["stable"]
    if "campbell_hz" in result:
        rpm = result["campbell_rpm"]
        bad = ~result["campbell_stable"]
        first = np.where(bad.any(axis=1), rpm[np.argmax(bad, axis=1)], np.nan)
        cols["campbell_unstable_from_rpm"] = np.where(result["code"] == _CODE["ok"], first, np.nan)
        if "campbell_mode_match" in result:
            cols["campbell_mode_match"] = result["campbell_mode_match"]
    return cols

def pooled(cols: Mapping[str, np.ndarray], result: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``cols`` with NaN in the flagged cases' rows (``result["flagged"]``: their numbers are kept in
    sweep.csv beside their status, but no statistic or figure pools them with the solved cases)."""
    flagged = np.asarray(result.get("flagged", False), bool)
    if not flagged.any():
        return dict(cols)
    return {k: np.where(flagged, np.nan, np.asarray(v, float)) if np.asarray(v).dtype.kind == "f" else v
            for k, v in cols.items()}


def statistics(x) -> dict[str, float | int | None]:
    """mean, std, min, max, p5, p50, p95 and count of the finite values of ``x``."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return dict(count=0, mean=None, std=None, min=None, max=None, p5=None, p50=None, p95=None)
    # about the largest magnitude's power of 2 (exact): no square or sum overflows, and no warning
    s = float(np.ldexp(1.0, int(np.frexp(np.max(np.abs(x)))[1]) - 1)) if np.any(x) else 1.0
    y = x / s
    p = np.percentile(y, [5, 50, 95]) * s
    return dict(count=int(x.size), mean=float(y.mean()) * s, std=float(y.std(ddof=1)) * s if x.size > 1 else 0.0,
                min=float(x.min()), max=float(x.max()), p5=float(p[0]), p50=float(p[1]), p95=float(p[2]))

def failures(result: Mapping[str, np.ndarray], max_cases: int = 20) -> dict:
    """{status: {count, reason, cases (first indices)}} of every case that is not "ok"."""
    out = {}
    for s in STATUS[1:]:
        idx = np.flatnonzero(result["status"] == s)
        if idx.size:
            out[s] = dict(count=int(idx.size), reason=REASONS[s], cases=[int(i) for i in idx[:max_cases]])
    return out

def _fmt(x) -> str:
    if isinstance(x, (bool, np.bool_)):
        return "1" if x else "0"
    if isinstance(x, str):
        return x
    x = float(x)
    return "nan" if not math.isfinite(x) else repr(x)

def write_csv(path: Path, values: Mapping[str, np.ndarray], cols: Mapping[str, np.ndarray], status) -> None:
    """sweep.csv: case, parameter columns (paths), output columns, status."""
    n = len(status)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", *values, *cols, "status"])
        for i in range(n):
            w.writerow([i, *(_fmt(v[i]) for v in values.values()), *(_fmt(c[i]) for c in cols.values()), status[i]])

def write_campbell_csv(path: Path, result: Mapping[str, np.ndarray]) -> None:
    """sweep_campbell.csv: one row per case and speed: case, rpm, f<k>_hz, stable."""
    F, ok, rpm = result["campbell_hz"], result["campbell_stable"], result["campbell_rpm"]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", "rpm", *(f"f{m + 1}_hz" for m in range(F.shape[2])), "stable"])
        for i in range(F.shape[0]):
            for j, r in enumerate(rpm):
                w.writerow([i, _fmt(r), *(_fmt(x) for x in F[i, j]), _fmt(ok[i, j])])

#: the columns a tolerance study is read for first (the summary table's and the histograms' lead)
LEAD_COLUMNS = ("arm_p2p_deg", "dynamic_min_slip_margin", "min_slip_margin")


def summary_table(cols: Mapping[str, np.ndarray], stats: Mapping[str, dict], labels: list[str] | None = None,
                  max_rows: int = 40) -> str:
    """A readable table of the statistics of the output columns (a response's arm motion and least
    slip margins first: a tolerance study is read for them)."""
    first = [c for c in LEAD_COLUMNS if c in cols]
    names = []
    for name in [*first, *(c for c in cols if c not in first)][:max_rows]:
        if name in ("converged", "stable"):
            continue
        lab = name
        if labels and name.startswith("f") and name[1:-3].isdigit() and int(name[1:-3]) - 1 < len(labels):
            lab = f"{name} {labels[int(name[1:-3]) - 1]}"
        names.append((name, lab))
    w = max([len("output"), *(len(lab) for _, lab in names)])  # the longest name, never cut
    lines = [f"{'output':<{w}} {'mean':>11} {'std':>10} {'min':>11} {'max':>11} {'p5':>11} {'p95':>11}"]
    f = lambda x: f"{x:>11.5g}" if x is not None else f"{'-':>11}"  # noqa: E731
    for name, lab in names:
        s = stats[name]
        lines.append(f"{lab:<{w}} {f(s['mean'])} {f(s['std'])[1:]} {f(s['min'])} {f(s['max'])} {f(s['p5'])} "
                     f"{f(s['p95'])}")
    if len(cols) > max_rows:
        lines.append(f"({len(cols) - max_rows} more columns in sweep.json)")
    return "\n".join(lines)

def report(scene: Scene, spec: Spec, values: Mapping[str, np.ndarray], result: Mapping[str, np.ndarray],
           nominal: tuple[list[str], list[float]] | None = None, timing: Mapping[str, Any] | None = None) -> dict:
    """sweep.json contents: the spec, the statistics of every output column, the failures by
    cause, the nominal scene's modes and ``timing`` (wall time, cases per second...)."""
    cols = columns(scene, result)
    fails = failures(result)
    flagged = np.asarray(result.get("flagged", np.zeros(len(result["status"]), bool)), bool)
    return {
        "scene": str(scene.source),
        "sweep_file": str(spec.source),
        "spec": spec.raw,
        "description": spec.description,
        "n_cases": len(result["status"]),
        "parameters": {p: statistics(v) for p, v in values.items()},
        "nominal": {p: nominal_value(scene, p) for p in spec.parameters},
        "outputs": list(spec.outputs),
        "columns": ["case", *values, *cols, "status"],
        "nominal_modes": None if nominal is None else {"labels": nominal[0], "frequencies_hz": nominal[1]},
        "frequency_columns": _columns_meaning(result),
        "summary": {k: statistics(v) for k, v in pooled(cols, result).items() if k not in ("converged", "stable")},
        "ok": int(np.sum(result["status"] == "ok")),
        "flagged": int(flagged.sum()),
        "failed": int(sum(v["count"] for k, v in fails.items() if k != "unstable")) - int(flagged.sum()),
        "unstable": fails.get("unstable", {}).get("count", 0),
        "failures": fails,
        "slipping": slipping(cols),
        **(timing or {}),
    }


#: the slip-margin columns a sweep warns on: (column, where the margin is taken)
SLIP_COLUMNS = (("min_slip_margin", "at the operating point"), ("dynamic_min_slip_margin", "during the steady cycle"))


def slipping(cols: Mapping[str, np.ndarray]) -> dict:
    """The cases whose least slip margin is <= 0 (an arc's friction cannot carry its tension ratio:
    the belt would slip; the model without ``belt_slip`` does not let it), per column of
    SLIP_COLUMNS present: {column: {"where", "count", "cases"}}."""
    out = {}
    for c, where in SLIP_COLUMNS:
        if c in cols:
            bad = np.flatnonzero(np.asarray(cols[c], float) <= 0.0)
            out[c] = {"where": where, "count": int(bad.size), "cases": bad[:20].tolist()}
    return out

def _columns_meaning(result: Mapping[str, Any]) -> str | None:
    """What the f<k>_hz (and sweep_campbell.csv) columns hold, for sweep.json."""
    if "frequencies_hz" not in result and "campbell_hz" not in result:
        return None
    if result.get("mode_labels") or result.get("campbell_mode_labels"):
        return ("f<k>_hz: the nominal scene's k-th mode (nominal_modes), followed into every case by its shape "
                "(mass-weighted MAC, optimal assignment; NaN: not found); mode_match: a case's lowest MAC")
    return "f<k>_hz: the k-th lowest frequency of each case (sorted: the nominal scene has no modes to follow)"

from beltjax.outputs import jsonable as _jsonable  # noqa: E402,F401  (the one converter)
