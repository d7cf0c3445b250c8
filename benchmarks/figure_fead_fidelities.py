"""The eight-pulley drive's idle second in both fidelities: rotational and hybrid (ANCF, 8
elements per span), side by side.

Run: ``.venv/bin/python benchmarks/figure_fead_fidelities.py`` (about 2 min); writes
``benchmarks/figures/fead_8pulley_fidelities.png`` and ``benchmarks/results/fead_fidelities.json``
and prints the table the README quotes.

``scenes/fead_8pulley.toml`` as shipped (800 rpm idle, the crank's 2nd and 4th orders, the
accessory loads), 1 s from the operating point; the hybrid model at 8 elements per span with its
defaults (generalized-alpha, dt = 1e-4 s).  Statistics over the last 0.5 s (after the start).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import dataclasses
from pathlib import Path

import numpy as np

from beltjax import transient
from beltjax.plotting import save, subplots
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
T_END, SETTLE = 1.0, 0.5


def _stats(res, name, j=None):
    late = res.t >= SETTLE
    x = res.channels[name][late] if j is None else res.channels[name][late, j]
    return float(np.mean(x)), float(np.ptp(x))


def main():
    base = load_scene(ROOT / "scenes" / "fead_8pulley.toml")
    runs = {}
    for fid, kw in (("rotational", {}), ("hybrid", dict(fidelity="ancf", elements_per_span=8))):
        sc = dataclasses.replace(base, model=dataclasses.replace(base.model, **kw)) if kw else base
        runs[fid] = transient.simulate(sc, T_END)
        print(f"{fid}: {runs[fid].meta['steps']} steps, {runs[fid].meta['wall_s']:.1f} s "
              f"(first chunk, compiling: {runs[fid].meta['first_chunk_s']:.1f} s); "
              f"warnings: {transient.run_warnings(runs[fid].meta) or 'none'}", flush=True)
    rot, hyb = runs["rotational"], runs["hybrid"]
    spans = rot.columns["span_tensions_N"]
    rows, table = [], []
    for j, s in enumerate(spans):
        (mr, pr), (mh, ph) = _stats(rot, "span_tensions_N", j), _stats(hyb, "span_tensions_N", j)
        rows.append(dict(span=s, rotational_mean_N=mr, hybrid_mean_N=mh, rotational_p2p_N=pr, hybrid_p2p_N=ph))
        table.append(f"| {s} | {mr:.1f} | {mh:.1f} | {pr:.1f} | {ph:.1f} |")
    (ar, apr), (ah, aph) = _stats(rot, "arm_angle_deg"), _stats(hyb, "arm_angle_deg")
    table.append(f"| tensioner arm [deg] | {ar:.2f} | {ah:.2f} | {apr:.3f} | {aph:.3f} |")
    header = ["| span tension [N] | mean, rotational | mean, hybrid | peak to peak, rotational | peak to peak, hybrid |",
              "|---|---|---|---|---|"]
    print("\n".join(header + table))

    n = len(spans)
    fig, axes = subplots(3, 3, figsize=(12.5, 8.0), sharex=True)
    flat = axes.ravel()
    late = (rot.t >= SETTLE)
    lateh = (hyb.t >= SETTLE)
    for j in range(n):
        ax = flat[j]
        ax.plot(rot.t[late], rot.channels["span_tensions_N"][late, j], lw=0.9, label="rotational")
        ax.plot(hyb.t[lateh], hyb.channels["span_tensions_N"][lateh, j], lw=0.7, label="hybrid, 8 elements/span")
        ax.set_title(spans[j], fontsize=9)
        ax.set_ylabel("tension [N]")
    ax = flat[n]
    ax.plot(rot.t[late], rot.channels["arm_angle_deg"][late], lw=0.9)
    ax.plot(hyb.t[lateh], hyb.channels["arm_angle_deg"][lateh], lw=0.7)
    ax.set_title("tensioner arm", fontsize=9)
    ax.set_ylabel("angle [deg]")
    for ax in flat[n + 1:]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    flat[0].legend(fontsize=8)
    fig.suptitle("eight-pulley drive at 800 rpm idle, 2nd and 4th crank orders: both fidelities (last 0.5 s)",
                 fontsize=10)
    out = ROOT / "benchmarks" / "figures" / "fead_8pulley_fidelities.png"
    save(fig, out, top_in=0.4)
    summary = dict(spans=rows, arm=dict(rotational_mean_deg=ar, hybrid_mean_deg=ah, rotational_p2p_deg=apr,
                                        hybrid_p2p_deg=aph),
                   runs={k: dict(steps=int(r.meta["steps"]), wall_s=float(r.meta["wall_s"]),
                                 first_chunk_s=float(r.meta["first_chunk_s"]), warnings=transient.run_warnings(r.meta))
                         for k, r in runs.items()},
                   table="\n".join(header + table))
    path = _common.save_json("fead_fidelities", summary)
    print(f"wrote {out.relative_to(ROOT)} and {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
