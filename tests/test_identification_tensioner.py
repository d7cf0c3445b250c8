"""Tensioner torque–angle identification (identification/torque_angle.py).

Synthetic loops (seeded, made here: a quasi-static sinusoidal sweep of the arm angle through a
Dahl dry-friction model, noise on angle and moment) with known k, theta_0 and friction band must
be recovered within 3 reported standard errors and a stated tolerance; the reported standard
errors must be honest (z-scores over 40 seeds have a standard deviation near 1); the shipped
example (identification/examples/tensioner_torque_angle, the thesis' k = 21.14 N m/rad and
theta_0 = 94.5 deg read from the reference) must fit; each kind of bad data raises DataError with a
one-line message naming the key or file.  All of it runs in a few seconds (linear least squares).
"""

from __future__ import annotations

import json
import math
import pathlib
import tomllib

import numpy as np
import pytest

from identification.data import DataError
from identification.torque_angle import branch_directions, fit_torque_angle

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "identification" / "examples" / "tensioner_torque_angle"


def loop(k=18.0, theta0=100.0, band=1.2, slope_per_deg=0.0, lo=25.0, hi=70.0, cycles=3, per_cycle=200,
         noise_angle=0.02, noise_torque=0.05, stick=800.0, seed=0):
    """(angle_deg, torque_Nm in the spring's sense) of a quasi-static loop with Dahl friction.

    The band is band + slope (theta - mid) (N m), mid the middle of the travel."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, cycles, cycles * per_cycle, endpoint=False)
    theta = (lo + hi) / 2 + (hi - lo) / 2 * np.cos(2 * np.pi * s)
    Tc = band + slope_per_deg * (theta - (lo + hi) / 2)
    F = np.empty_like(theta)
    F[0] = Tc[0]
    for i in range(1, theta.size):
        step = math.radians(theta[i] - theta[i - 1])
        target = Tc[i] * np.sign(step)
        F[i] = target + (F[i - 1] - target) * math.exp(-stick * abs(step) / Tc[i])
    torque = k * np.radians(theta0 - theta) - F
    return theta + rng.normal(0, noise_angle, theta.size), torque + rng.normal(0, noise_torque, theta.size)


def write(path: pathlib.Path, columns: dict, comment: str | None = "# synthesised by the test") -> str:
    names = list(columns)
    rows = zip(*(columns[n] for n in names))
    lines = ([comment] if comment else []) + [",".join(names)] + [",".join(f"{v:.6f}" for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path.name


def fit_loop(tmp_path, angle, torque, name="loop.csv", **section):
    write(tmp_path / name, {"angle_deg": angle, "torque_Nm": torque})
    return fit_torque_angle({"file": name, **section}, tmp_path)


def within(value, true, se, rel=None, abs_=None):
    """|value - true| within 3 standard errors and within the stated tolerance."""
    assert abs(value - true) <= 3 * se, (value, true, se)
    tol = rel * abs(true) if rel is not None else abs_
    assert abs(value - true) <= tol, (value, true, tol)


# --------------------------------------------------------------------------- recovery


def test_branch_directions_ignore_noise_below_the_threshold():
    """Turning points are found where the angle comes back by more than the threshold; noise of
    a tenth of it never flips the branch; samples within the threshold of a turning point's
    angle (either side) are flagged by their margin, and all others have the true branch."""
    rng = np.random.default_rng(1)
    s = np.linspace(0, 2, 400, endpoint=False)
    th = 50 + 20 * np.cos(2 * np.pi * s) + rng.normal(0, 0.05, s.size)
    d, margin = branch_directions(th, 0.5)
    true = -np.sign(np.sin(2 * np.pi * s))  # d theta / ds < 0 on the first half-cycle
    ok = (d != 0) & (margin >= 0.5)
    assert np.all(d[ok] == true[ok])
    assert ok.sum() > 0.85 * s.size
    assert np.count_nonzero(np.diff(d[d != 0])) == 3  # four half-cycles, three reversals


def test_recovers_constant_band(tmp_path):
    """k = 18 N m/rad, theta_0 = 100 deg, band 1.2 N m, noise 0.02 deg / 0.05 N m, 25-70 deg:
    within 3 sigma and 0.3 % (k), 0.1 deg (theta_0), 0.01 N m (band)."""
    fit = fit_loop(tmp_path, *loop())
    print("\n" + fit.table())
    within(fit.spring_stiffness_Nm_per_rad, 18.0, fit.spring_stiffness_se, rel=3e-3)
    within(fit.spring_preload_deg, 100.0, fit.spring_preload_se, abs_=0.1)
    within(fit.friction_band_Nm, 1.2, fit.friction_band_se, abs_=0.01)
    assert fit.friction_slope_Nm_per_deg is None
    assert fit.friction_band_spread_Nm < 0.05  # a constant band: the local half-widths agree
    assert 0.045 < fit.residual_rms_Nm < 0.056  # the torque noise (0.05) and k x angle noise (0.006)
    assert fit.n_used < fit.n_points  # the stick segments at the turning points are left out


def test_recovers_linear_band(tmp_path):
    """A band that narrows with the angle (-0.02 N m/deg, the thesis' wider loop at high moment),
    friction = "linear": slope within 3 sigma and 5 %; the constant-band fit of the same data
    reports the variation as its spread."""
    angle, torque = loop(k=21.14, theta0=94.5, band=1.8, slope_per_deg=-0.02, lo=20, hi=75, seed=2)
    fit = fit_loop(tmp_path, angle, torque, friction="linear")
    print("\n" + fit.table())
    within(fit.spring_stiffness_Nm_per_rad, 21.14, fit.spring_stiffness_se, rel=3e-3)
    within(fit.spring_preload_deg, 94.5, fit.spring_preload_se, abs_=0.1)
    band_at = 1.8 - 0.02 * (fit.friction_band_at_deg - 47.5)
    within(fit.friction_band_Nm, band_at, fit.friction_band_se, abs_=0.01)
    within(fit.friction_slope_Nm_per_deg, -0.02, fit.friction_slope_se, rel=0.05)
    constant = fit_loop(tmp_path, angle, torque)
    assert constant.friction_band_spread_Nm > 0.25  # 55 deg x 0.02 N m/deg over ten bins
    assert abs(constant.friction_band_Nm - band_at) < 0.05


def test_standard_errors_are_honest(tmp_path):
    """Over 40 seeds the z-scores (estimate - truth) / se of k, theta_0 and the band have a
    standard deviation within [0.7, 1.4] and a mean within 0.5 of 0."""
    z = []
    for seed in range(40):
        angle, torque = loop(seed=100 + seed, cycles=2, per_cycle=150)
        f = fit_loop(tmp_path, angle, torque)
        z.append([(f.spring_stiffness_Nm_per_rad - 18.0) / f.spring_stiffness_se,
                  (f.spring_preload_deg - 100.0) / f.spring_preload_se,
                  (f.friction_band_Nm - 1.2) / f.friction_band_se])
    z = np.asarray(z)
    print(f"\n  z std {z.std(axis=0)}, mean {z.mean(axis=0)}")
    assert np.all((z.std(axis=0) > 0.7) & (z.std(axis=0) < 1.4))
    assert np.all(np.abs(z.mean(axis=0)) < 0.5)


def test_applied_moment_and_recorded_angle_conventions(tmp_path):
    """The same loop as the applied moment (CCW) and as a deflection read clockwise from 100 deg:
    torque_sign = "applied", angle_offset_deg = 100, angle_sense = "cw" give the same fit; an
    explicit direction column gives it too."""
    angle, torque = loop(seed=3)
    ref = fit_loop(tmp_path, angle, torque)
    fit = fit_loop(tmp_path, 100.0 - angle, -torque, name="applied.csv",
                   torque_sign="applied", angle_offset_deg=100.0, angle_sense="cw")
    # (equal to the CSV's 6 decimals: 1e-6 deg of rounding)
    assert abs(fit.spring_stiffness_Nm_per_rad / ref.spring_stiffness_Nm_per_rad - 1) < 1e-5
    assert abs(fit.spring_preload_deg - ref.spring_preload_deg) < 1e-4
    assert abs(fit.friction_band_Nm - ref.friction_band_Nm) < 1e-4
    d = np.where(ref.used, ref.direction, 0)
    write(tmp_path / "dir.csv", {"angle_deg": angle, "torque_Nm": torque, "dir": d})
    fit = fit_torque_angle({"file": "dir.csv", "direction_column": "dir"}, tmp_path)
    assert abs(fit.spring_stiffness_Nm_per_rad / ref.spring_stiffness_Nm_per_rad - 1) < 1e-12


# --------------------------------------------------------------------------- the shipped example


def test_example_dataset(ref, tmp_path):
    """identification/examples/tensioner_torque_angle: synthesised from the thesis' spring (read
    from the reference here) with a band growing with the moment: k within 3 sigma and 0.5 %,
    theta_0 within 3 sigma and 0.2 deg, band and slope within 3 sigma and 2 % / 5 %; the outputs
    (JSON, table, TOML [tensioner] block, plot) are well formed."""
    tens = ref["bench"]["tensioner"]
    k, theta0 = tens["spring_stiffness_Nm_per_rad"], tens["spring_preload_angles_deg"][1]
    data = tomllib.loads((EXAMPLE / "dataset.toml").read_text())
    fit = fit_torque_angle(data["torque_angle"], EXAMPLE)
    exp = json.loads((EXAMPLE / "expected.json").read_text())
    assert exp["spring_stiffness_Nm_per_rad"] == k and exp["spring_preload_deg"] == theta0
    print("\n" + fit.table())
    within(fit.spring_stiffness_Nm_per_rad, k, fit.spring_stiffness_se, rel=5e-3)
    within(fit.spring_preload_deg, theta0, fit.spring_preload_se, abs_=0.2)
    spring_at = k * math.radians(theta0 - fit.friction_band_at_deg)
    band = exp["friction_band_base_Nm"] + exp["friction_band_share"] * spring_at
    within(fit.friction_band_Nm, band, fit.friction_band_se, rel=0.02)
    within(fit.friction_slope_Nm_per_deg, exp["friction_slope_Nm_per_deg"], fit.friction_slope_se, rel=0.05)
    out = fit.to_json()
    assert json.loads(json.dumps(out)) == out
    assert out["spring_stiffness_Nm_per_rad"] == fit.spring_stiffness_Nm_per_rad
    block = tomllib.loads(fit.scene_block())["tensioner"]
    assert abs(block["spring_stiffness"] / k - 1) < 5e-3 and abs(block["spring_preload_deg"] - theta0) < 0.2
    assert "friction" in fit.scene_block() and "N m/rad" in fit.table()
    paths = fit.plot(tmp_path / "plots")
    assert paths and all(p.is_file() and p.stat().st_size > 10_000 for p in paths)


# --------------------------------------------------------------------------- bad data


def _error(tmp_path, section, match):
    with pytest.raises(DataError, match=match) as e:
        fit_torque_angle(section, tmp_path)
    msg = str(e.value)
    assert "\n" not in msg and "torque_angle" in msg
    return msg


def test_bad_data_raises_one_line_errors(tmp_path):
    """Missing file, missing column, empty file, too few rows, unknown key or option: DataError
    naming the key and the file."""
    angle, torque = loop(seed=4)
    write(tmp_path / "ok.csv", {"angle_deg": angle, "torque_Nm": torque})
    _error(tmp_path, {}, r"torque_angle\.file: missing")
    _error(tmp_path, {"file": "nope.csv"}, "nope.csv.*not found")
    write(tmp_path / "nocol.csv", {"angle_deg": angle, "moment": torque})
    _error(tmp_path, {"file": "nocol.csv"}, r"nocol\.csv.*lacks column.*torque_Nm")
    (tmp_path / "empty.csv").write_text("# nothing here\n")
    _error(tmp_path, {"file": "empty.csv"}, r"empty\.csv is empty")
    write(tmp_path / "few.csv", {"angle_deg": angle[:5], "torque_Nm": torque[:5]})
    _error(tmp_path, {"file": "few.csv"}, r"few\.csv has 5 data rows")
    _error(tmp_path, {"file": "ok.csv", "torque_sing": "spring"}, r"torque_angle\.torque_sing: unknown key")
    _error(tmp_path, {"file": "ok.csv", "torque_sign": "up"}, r"torque_angle\.torque_sign: must be one of")
    _error(tmp_path, {"file": "ok.csv", "angle_offset_deg": "ten"}, r"torque_angle\.angle_offset_deg: must be a number")


def test_non_identifiable_loops_say_which_parameter(tmp_path):
    """An angle range under 1 deg, or a few degrees drowned in noise: spring_stiffness not
    identifiable; a one-way sweep: both branches needed; the applied moment read as the
    spring's: k negative, with the torque_sign hint; the rows in reverse time order: the loop
    runs the wrong way round."""
    a, T = loop(lo=50.0, hi=50.6, seed=5)
    msg = _error(tmp_path, {"file": write(tmp_path / "narrow.csv", {"angle_deg": a, "torque_Nm": T})},
                 r"spans only 0\.\d+ deg")
    assert "spring_stiffness (k) is not identifiable" in msg
    a, T = loop(lo=50.0, hi=53.0, noise_torque=2.0, seed=6)
    _error(tmp_path, {"file": write(tmp_path / "noisy.csv", {"angle_deg": a, "torque_Nm": T})},
           r"noisy\.csv: spring_stiffness \(k\) not identifiable")
    a, T = loop(seed=7)
    half = slice(0, 100)  # the first half-cycle: the angle only falls
    _error(tmp_path, {"file": write(tmp_path / "oneway.csv", {"angle_deg": a[half], "torque_Nm": T[half]})},
           r"oneway\.csv: fewer than 3 points with the angle rising.*not identifiable")
    _error(tmp_path, {"file": write(tmp_path / "applied.csv", {"angle_deg": a, "torque_Nm": -T})},
           r"applied\.csv: spring_stiffness \(k\) not identifiable.*torque_sign = \"applied\"")
    _error(tmp_path, {"file": write(tmp_path / "reversed.csv", {"angle_deg": a[::-1], "torque_Nm": T[::-1]})},
           r"reversed\.csv: the loop runs the wrong way round")
