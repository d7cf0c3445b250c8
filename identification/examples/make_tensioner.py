"""Synthesise the tensioner torque–angle example (``tensioner_torque_angle/``).

SYNTHESISED, not measured: the thesis prints no torque–angle samples (only the fitted spring,
Figs. 6.14–6.15).  The loop is made from the thesis' published tensioner parameters, read from
../shared/reference/thesis_reference.json at generation time:

* spring stiffness k = ``bench.tensioner.spring_stiffness_Nm_per_rad`` (21.14 N m/rad),
* free angle theta_0 = ``bench.tensioner.spring_preload_angles_deg[1]`` (94.5 deg, the
  original preload, "curve 2"),

and invented test conditions like those of section 6.3: the arm driven sinusoidally at 0.1 Hz
(quasi-static) over 20–75 deg of arm angle, 3 cycles sampled at 20 Hz (600 rows), a dry-friction
band that grows with the spring moment as the thesis saw (T_c = 1.0 N m + 5 % of the spring
moment: 2.4 N m at 20 deg, 1.4 N m at 75 deg), entered through a Dahl model (stick stiffness
600 N m/rad, so each turning point shows a short steep stick segment), and white noise of
0.05 deg on the angle and 0.08 N m on the moment (seed 6_3).  The moment is written in the
spring's sense (``torque_sign = "spring"``).  Expected fit with ``friction = "linear"``: k and
theta_0 as above, band 1.0 + 0.05 k (theta_0 - theta_c) at the data's mean angle theta_c,
slope -0.05 k pi/180 = -0.0184 N m/deg (written to ``expected.json`` for the tests).

Run from the repository root: ``python identification/examples/make_tensioner.py``.
"""

from __future__ import annotations

import json
import math
import pathlib

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
REPO = HERE.parents[1]
REFERENCE = REPO.parent / "shared" / "reference" / "thesis_reference.json"
OUT = HERE / "tensioner_torque_angle"

ANGLES_DEG = (20.0, 75.0)  # arm travel in the test (deg)
FREQUENCY_HZ, CYCLES, RATE_HZ = 0.1, 3, 20.0
BAND_BASE_NM, BAND_SHARE = 1.0, 0.05  # friction band T_c = base + share * spring moment (N m)
STICK_NM_PER_RAD = 600.0  # Dahl stick stiffness
NOISE_ANGLE_DEG, NOISE_TORQUE_NM = 0.05, 0.08
SEED = 63


def synthesise(k: float, theta0_deg: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(angle_deg, torque_Nm) of the loop: true angle through a Dahl friction model, then noise."""
    t = np.arange(0.0, CYCLES / FREQUENCY_HZ, 1.0 / RATE_HZ)
    lo, hi = ANGLES_DEG
    # start at the top of the travel and go down first (winding the spring up: loading)
    theta = (lo + hi) / 2 + (hi - lo) / 2 * np.cos(2 * np.pi * FREQUENCY_HZ * t)
    spring = k * np.radians(theta0_deg - theta)
    band = BAND_BASE_NM + BAND_SHARE * spring
    F = np.empty_like(theta)
    F[0] = band[0]  # as if arriving from below
    for i in range(1, theta.size):
        step = math.radians(theta[i] - theta[i - 1])
        target = band[i] * np.sign(step) if step != 0 else F[i - 1]
        F[i] = target + (F[i - 1] - target) * math.exp(-STICK_NM_PER_RAD * abs(step) / band[i])
    torque = spring - F  # spring's sense: the friction moment opposes the motion
    return theta + rng.normal(0.0, NOISE_ANGLE_DEG, theta.size), torque + rng.normal(0.0, NOISE_TORQUE_NM, theta.size)


def main() -> None:
    ref = json.loads(REFERENCE.read_text())["bench"]["tensioner"]
    k = float(ref["spring_stiffness_Nm_per_rad"])
    theta0 = float(ref["spring_preload_angles_deg"][1])
    angle, torque = synthesise(k, theta0, np.random.default_rng(SEED))
    OUT.mkdir(exist_ok=True)
    src = "../shared/reference/thesis_reference.json bench.tensioner"
    lines = [
        f"# synthesised by identification/examples/make_tensioner.py from {src}: "
        f"k = {k} N m/rad, theta_0 = {theta0} deg (preload 2), Dahl dry friction "
        f"{BAND_BASE_NM} N m + {BAND_SHARE:g} x spring moment, noise {NOISE_ANGLE_DEG} deg / {NOISE_TORQUE_NM} N m",
        "angle_deg,torque_Nm",
    ]
    lines += [f"{a:.4f},{T:.4f}" for a, T in zip(angle, torque)]
    (OUT / "torque_angle.csv").write_text("\n".join(lines) + "\n")
    theta_c = float(np.mean(angle))
    band_c = BAND_BASE_NM + BAND_SHARE * k * math.radians(theta0 - theta_c)
    (OUT / "dataset.toml").write_text("\n".join([
        "# Tensioner torque-angle test (thesis section 6.3): SYNTHESISED by make_tensioner.py from the",
        f"# thesis' spring (k = {k} N m/rad, theta_0 = {theta0} deg; ../shared/reference/thesis_reference.json)",
        "# with an invented friction band and noise.",
        "# beltjax fit identification/examples/tensioner_torque_angle/dataset.toml",
        f"# Expected: k = {k}, theta_0 = {theta0} deg, band {band_c:.3f} N m "
        f"at {theta_c:.1f} deg, slope {-BAND_SHARE * k * math.pi / 180:.4f} N m/deg.",
        "[torque_angle]",
        'file = "torque_angle.csv"     # angle_deg: arm angle (deg, CCW from +x); torque_Nm: spring\'s sense',
        'torque_sign = "spring"',
        'friction = "linear"           # the band grows with the spring moment (thesis Fig. 6.14)',
        "",
    ]))
    expected = dict(
        source="synthesised by make_tensioner.py; k and theta_0 from " + src,
        spring_stiffness_Nm_per_rad=k,
        spring_preload_deg=theta0,
        friction_band="T_c(theta) = base + share * k * radians(theta_0 - theta)",
        friction_band_base_Nm=BAND_BASE_NM,
        friction_band_share=BAND_SHARE,
        friction_slope_Nm_per_deg=-BAND_SHARE * k * math.pi / 180,
    )
    (OUT / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")
    print(f"wrote {OUT / 'torque_angle.csv'} ({angle.size} rows), dataset.toml and expected.json")


if __name__ == "__main__":
    main()
