"""``beltjax orders``: the response over speed, its files (orders.json, orders.csv, orders.npz,
figures) and the printed summary."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from beltjax import outputs
from beltjax.orders.figures import plot_all
from beltjax.orders.run import RETRY_FACTOR, OrdersResult

#: most rows of the printed table (evenly spaced speeds beyond)
TABLE_ROWS = 40


def csv_columns(result: OrdersResult) -> list[tuple[str, np.ndarray]]:
    """(header, (S,) values) of every column of orders.csv: speed, settling, each statistic of
    each channel column, each order amplitude, each slip margin and friction need."""
    cols: list[tuple[str, np.ndarray]] = [("rpm", result.rpm), ("settling", result.settling)]
    for key, val in result.stats.items():
        if key in ("hub_forces_N", "t_s"):
            continue
        name, _, stat = key.partition(":")
        labels = result.columns.get(name) or [None]
        val = np.asarray(val).reshape(len(result.rpm), -1, len(result.orders) if stat == "orders" else 1)
        for j, lab in enumerate(labels[: val.shape[1]]):
            head = name if lab is None else f"{name}[{lab}]"
            if stat == "orders":
                for k, o in enumerate(result.orders):
                    cols.append((f"{head}:order_{o:g}", val[:, j, k]))
            else:
                cols.append((f"{head}:{stat}" if stat else head, val[:, j, 0]))
    return cols


def write_csv(result: OrdersResult, path: Path) -> None:
    """orders.csv: one row per speed (status, then :func:`csv_columns`)."""
    cols = csv_columns(result)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["rpm", "status", *[h for h, _ in cols[1:]]])
        for i in range(len(result.rpm)):
            w.writerow([f"{result.rpm[i]:.10g}", result.status[i], *[f"{float(v[i]):.10g}" for _, v in cols[1:]]])


def _where(rpm: np.ndarray, mask: np.ndarray) -> str:
    """The speeds where mask holds, as runs ``a-b`` (rpm)."""
    idx = np.flatnonzero(mask)
    runs, start = [], None
    for k, i in enumerate(idx):
        if start is None:
            start = i
        if k + 1 == len(idx) or idx[k + 1] != i + 1:
            runs.append(f"{rpm[start]:.0f}" if start == i else f"{rpm[start]:.0f}-{rpm[i]:.0f}")
            start = None
    return ", ".join(runs)


def _extreme(x: np.ndarray, pick) -> tuple | None:
    """The index of ``x``'s extreme finite value by ``pick`` (np.nanargmax or np.nanargmin), or
    None where no value is finite (every speed failed)."""
    x = np.where(np.isfinite(x), x, np.nan)
    return None if not np.isfinite(x).any() else np.unravel_index(int(pick(x)), x.shape)


def summary(result: OrdersResult) -> str:
    """The printed summary: speeds, flags, the worst arm motion, span swing and slip margin, a table."""
    rpm, st = result.rpm, np.asarray(result.status)
    m = result.meta
    revs = m["revolutions_per_cycle"]
    n_shot = m["methods"].count("shooting")
    longer = m["rerun_speeds"]  # (with the settling method: those run again longer)
    how = (f"by shooting at {n_shot}, a settling transient at {len(rpm) - n_shot}" if m["method"] == "shooting" else
           f"settled {m['settle_s']:g} s, {longer} speed{'' if longer == 1 else 's'} run again "
           f"{RETRY_FACTOR:g}x longer")
    lines = [f"  {len(rpm)} speeds {rpm.min():.0f}-{rpm.max():.0f} rpm, {m['fidelity']} model, a cycle of {revs} "
             f"crank revolution{'s' if revs > 1 else ''}; {how}",
             f"  {m['wall_s']:.1f} s"]
    for s in sorted(set(st) - {"ok"}):
        lines.append(f"  {s.replace('_', ' ')}: {_where(rpm, st == s)} rpm")
    arm = result.stats.get("arm_angle_deg:p2p")
    none = "none (no speed gave a result)"
    if arm is not None:
        at = _extreme(arm, np.nanargmax)
        if at is None:
            lines.append(f"  largest arm motion: {none}")
        else:
            i, = at
            k = int(np.argmax(result.stats["arm_angle_deg:orders"][i]))
            lines.append(f"  largest arm motion: {arm[i]:.3g} deg peak to peak at {rpm[i]:.0f} rpm "
                         f"(order {result.orders[k]:g}: {result.stats['arm_angle_deg:orders'][i, k]:.3g} deg amplitude)")
    ten = result.stats["span_tensions_N:p2p"]
    at = _extreme(ten, np.nanargmax)
    lines.append(f"  largest span tension swing: {none}" if at is None else
                 f"  largest span tension swing: {ten[at]:.4g} N peak to peak, span "
                 f"{result.columns['span_tensions_N'][at[1]]} at {rpm[at[0]]:.0f} rpm")
    margins = result.stats.get("min_slip_margin")
    if margins is not None:
        at = _extreme(margins, np.nanargmin)
        lines.append(f"  least slip margin: {none}" if at is None else
                     f"  least slip margin: {margins[at]:.3g} ({result.columns['min_slip_margin'][at[1]]}) at "
                     f"{rpm[at[0]]:.0f} rpm")
        for j, name in enumerate(result.columns["min_slip_margin"]):
            bad = margins[:, j] <= 0
            if bad.any():
                lines.append(f"  WARNING: {name} would slip at {_where(rpm, bad)} rpm (slip margin <= 0)")
    rows = np.arange(len(rpm))
    if len(rows) > TABLE_ROWS:
        k = -(-len(rpm) // TABLE_ROWS)
        rows = rows[::k]
        lines.append(f"  (every {k}{'nd' if k == 2 else 'rd' if k == 3 else 'th'} speed; all in orders.csv)")
    head = f"  {'rpm':>7}  {'status':<13} {'arm p2p deg':>11}  {'span p2p N':>10} {'span':<24} {'least margin':>12}"
    lines.append(head)
    for i in rows:
        j = int(np.nanargmax(ten[i])) if np.isfinite(ten[i]).any() else 0
        a = f"{arm[i]:11.3g}" if arm is not None else f"{'-':>11}"
        mg = f"{np.min(margins[i]):12.3g}" if margins is not None else f"{'-':>12}"
        lines.append(f"  {rpm[i]:7.0f}  {st[i]:<13} {a}  {ten[i, j]:10.4g} {result.columns['span_tensions_N'][j]:<24} {mg}")
    return "\n".join(lines)


def write(result: OrdersResult, out: Path, title: str) -> list[Path]:
    """orders.json, orders.csv, orders.npz (the hub-force loci and times of each cycle) and the
    figures, into ``out``."""
    out = Path(out)
    outputs.write_json(out / "orders.json", result.to_json())
    write_csv(result, out / "orders.csv")
    np.savez_compressed(out / "orders.npz", rpm=result.rpm, hub_forces_N=result.stats["hub_forces_N"],
                        t_s=result.stats["t_s"], hub_columns=np.asarray(result.columns["hub_forces_N"]))
    return [out / "orders.json", out / "orders.csv", out / "orders.npz", *plot_all(result, out, title=title)]
