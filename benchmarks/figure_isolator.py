"""The crank isolator's effect over engine speed: the eight-pulley drive with and without an
isolator pulley on its crank, responses over speed side by side.

Run: ``python benchmarks/figure_isolator.py`` (about 2 min); writes
``benchmarks/figures/isolator_fead_8pulley.png`` and ``benchmarks/results/isolator.json`` and
prints the peaks the README quotes.

Both drives: ``scenes/fead_8pulley.toml`` (2nd and 4th crank orders falling with speed), 600 to
6000 rpm in steps of 100 rpm, 1 s of settling (``beltjax orders``' defaults).  The isolated one
adds ``[isolator] pulley = "crank"``, stiffness 400 N m/rad, damping 0.3 N m s/rad: with the
crank pulley's 8.0e-3 kg m^2 its own mode is near 36 Hz on a fixed belt.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import json
from pathlib import Path

import numpy as np

from beltjax import orders
from beltjax.plotting import save, subplots
from beltjax.scene import loads_scene

ROOT = Path(__file__).resolve().parents[1]
ISOLATOR = '\n[isolator]\npulley = "crank"\nstiffness = 400.0\ndamping = 0.3\n'


def main():
    base = (ROOT / "scenes" / "fead_8pulley.toml").read_text()
    rpm = np.arange(600.0, 6001.0, 100.0)
    runs = {}
    for name, text in (("rigid crank pulley", base), ("isolator 400 N m/rad", base + ISOLATOR)):
        r = orders.response_over_speed(loads_scene(text), rpm)
        runs[name] = r
        ten = r.channel("span_tensions_N", "p2p")
        arm = r.channel("arm_angle_deg", "p2p")
        j = r.columns["span_tensions_N"].index("crank-ac")
        bad = [f"{x:.0f}" for x, s in zip(rpm, r.status) if s != "ok"]
        print(f"{name:<22} largest span swing {ten.max():7.1f} N at {rpm[np.argmax(ten.max(axis=1))]:.0f} rpm; "
              f"crank-ac at 800 rpm {ten[2, j]:6.1f} N; arm p2p max {arm.max():.3g} deg at "
              f"{rpm[np.argmax(arm)]:.0f} rpm; not ok at {', '.join(bad) or 'none'} rpm")
    fig, axes = subplots(1, 3, figsize=(13.5, 3.6))
    for name, r in runs.items():
        ten = r.channel("span_tensions_N", "p2p")
        axes[0].plot(rpm, ten.max(axis=1), label=name)
        axes[1].plot(rpm, r.channel("arm_angle_deg", "p2p"), label=name)
        axes[2].plot(rpm, np.clip(r.stats["min_slip_margin"].min(axis=1), -1.0, 1.0), label=name)
    axes[0].set_ylabel("largest span tension swing, p2p [N]")
    axes[1].set_ylabel("tensioner arm, p2p [deg]")
    axes[2].set_ylabel("least slip margin (clipped) [-]")
    axes[2].axhline(0.0, color="k", lw=0.6)
    for ax in axes:
        ax.set_xlabel("crank speed [rpm]")
    axes[0].legend(fontsize=8)
    fig.suptitle("eight-pulley drive (scenes/fead_8pulley.toml): crank isolator against a rigid crank pulley",
                 fontsize=10)
    out = ROOT / "benchmarks" / "figures" / "isolator_fead_8pulley.png"
    save(fig, out, top_in=0.4)
    data = {name: dict(rpm=rpm, status=r.status, span_p2p_max_N=r.channel("span_tensions_N", "p2p").max(axis=1),
                       arm_p2p_deg=r.channel("arm_angle_deg", "p2p"),
                       min_slip_margin=r.stats["min_slip_margin"].min(axis=1)) for name, r in runs.items()}
    path = _common.save_json("isolator", dict(runs=data))
    print(f"wrote {out.relative_to(ROOT)} and {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
