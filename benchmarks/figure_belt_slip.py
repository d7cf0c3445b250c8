"""Gross slip on the eight-pulley drive: an A/C clutch engagement at idle, with ``belt_slip``.

Run: ``python benchmarks/figure_belt_slip.py`` (about 2 min); writes
``benchmarks/figures/belt_slip_fead_8pulley.png`` and ``benchmarks/results/belt_slip_fead.json``
and prints the numbers the README quotes.

``scenes/fead_8pulley.toml`` (rotational, 800 rpm idle, 2nd and 4th crank orders) with
``belt_slip`` listed and the A/C compressor's load raised by 10 N m from t = 0.2 s to 0.35 s (a
clutch engagement's torque spike on top of its 6 N m): 0.6 s of transient, at the default
``belt.slip_speed`` and, for what the regularisation changes, at 10 and 1000 m/s.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import math
from pathlib import Path

import numpy as np

from beltjax import transient
from beltjax.plotting import save, subplots
from beltjax.scene import loads_scene

ROOT = Path(__file__).resolve().parents[1]
PULSE = '\n[[torque]]\npulley = "ac"\nmean_Nm = 10.0\nt_start_s = 0.2\nt_end_s = 0.35\n'


def main():
    text = (ROOT / "scenes" / "fead_8pulley.toml").read_text()
    text = text.replace('effects = ["transport"', 'effects = ["belt_slip", "transport"', 1) + PULSE
    sc = loads_scene(text)
    res = transient.simulate(sc, 0.6)
    c, t = res.channels, res.t
    order = list(sc.route.order)
    radii = np.array([float(sc.tensioner.pulley_radius) if n == "tensioner" else float(sc.pulley(n).radius)
                      for n in order])
    rim = np.abs(c["pulley_speeds_rpm"]) * math.pi / 30 * radii  # m/s
    slip = c["slip_speeds_m_s"]
    sliding = [i for i in range(len(order)) if np.max(np.abs(slip[:, i])) > 1e-6]
    energy = float(np.trapezoid(c["friction_power_W"], t))
    during = (t >= 0.2) & (t < 0.35)
    belt = rim[:, 0] + slip[:, 0] + c["creep_speeds_m_s"][:, 0]  # leaving the crank: rim, slide, creep
    fig, axes = subplots(1, 3, figsize=(13.5, 3.6))
    for i in (0, 1):
        axes[0].plot(t, rim[:, i], label=f"{order[i]} rim")
    axes[0].plot(t, belt, "k--", lw=0.8, label="belt, crank-ac span")
    axes[0].set_ylabel("speed [m/s]")
    for i in sliding:
        axes[1].plot(t, slip[:, i], label=order[i])
    axes[1].set_ylabel("belt sliding over the rim, gross [m/s]")
    axes[2].plot(t, c["friction_power_W"], color="C3")
    axes[2].set_ylabel("belt friction power [W]")
    for ax in axes:
        ax.set_xlabel("time [s]")
        ax.axvspan(0.2, 0.35, color="0.9", zorder=0)
    axes[0].legend(fontsize=8)
    axes[1].legend(fontsize=8)
    fig.suptitle("eight-pulley drive at idle with belt_slip: A/C load +10 N m from 0.2 to 0.35 s (shaded)", fontsize=10)
    out = ROOT / "benchmarks" / "figures" / "belt_slip_fead_8pulley.png"
    save(fig, out, top_in=0.4)
    summary = dict(sliding=[order[i] for i in sliding],
                   peak_slip_m_s={order[i]: float(np.max(np.abs(slip[:, i]))) for i in sliding},
                   ac_min_speed_rpm=float(np.min(np.abs(c["pulley_speeds_rpm"][:, 1]))),
                   friction_energy_J=energy, peak_friction_power_W=float(np.max(c["friction_power_W"])),
                   mean_creep_power_before_W=float(np.mean(c["friction_power_W"][t < 0.2])),
                   steps=int(res.meta["steps"]), wall_s=float(res.meta["wall_s"]),
                   slipping_reported=[r["pulley"] for r in res.meta["slipping_pulleys"]],
                   min_belt_speed_m_s=float(np.min(belt)))
    print(f"sliding: {', '.join(f'{k} up to {v:.2f} m/s' for k, v in summary['peak_slip_m_s'].items())}; "
          f"A/C down to {summary['ac_min_speed_rpm']:.0f} rpm; friction energy {energy:.0f} J "
          f"(peak {summary['peak_friction_power_W']:.0f} W; creep before the pulse {summary['mean_creep_power_before_W']:.2f} W); "
          f"the belt slows to {np.min(belt):.2f} m/s (the crank's rim {np.mean(rim[during, 0]):.2f} m/s); "
          f"{res.meta['steps']} steps, {res.meta['wall_s']:.1f} s")
    sens = {}
    for vr in (10.0, 1000.0):  # what the regularisation changes in this event
        r = transient.simulate(loads_scene(text.replace("groove_angle_deg = 40.0", f"groove_angle_deg = 40.0\n"
                                                                              f"slip_speed = {vr}", 1)), 0.6)
        sens[vr] = dict(friction_energy_J=float(np.trapezoid(r.channels["friction_power_W"], r.t)),
                        peak_crank_slip_m_s=float(np.max(np.abs(r.channels["slip_speeds_m_s"][:, 0]))),
                        steps=int(r.meta["steps"]), wall_s=float(r.meta["wall_s"]))
        print(f"  belt.slip_speed {vr:g} m/s: friction energy {sens[vr]['friction_energy_J']:.0f} J, crank sliding up "
              f"to {sens[vr]['peak_crank_slip_m_s']:.2f} m/s, {sens[vr]['steps']} steps, {sens[vr]['wall_s']:.1f} s")
    summary["slip_speed_sensitivity"] = {str(k): v for k, v in sens.items()}
    path = _common.save_json("belt_slip_fead", summary)
    print(f"wrote {out.relative_to(ROOT)} and {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
