"""Tensioner torque–angle tests: spring stiffness, free angle and dry-friction band (thesis 6.3).

The thesis turns the tensioner arm slowly (0.1 Hz, quasi-static) through a wide angle and
records the moment and the angle; the loop shows hysteresis from dry friction: the moment
needed to wind the spring up (loading) is higher than the one while it unwinds (unloading)
at the same angle.  This module fits, by linear least squares,

    T(theta, d) = k (theta_0 - theta) - d T_f(theta),     T_f(theta) = T_f [+ s (theta - theta_c)]

to the loop, where T is the moment in the sense in which the spring pushes the arm (the scene's
spring moment is ``-k (theta - theta_0)``, DESIGN.md), theta the arm angle, ``d = +1`` while the
angle increases and ``-1`` while it decreases (friction opposes the motion), k the stiffness
(N m/rad), theta_0 the free (preload) angle where the mean spring moment is zero, and T_f the
friction band: half the loop's width (N m), constant or, with ``friction = "linear"``, varying
linearly with the angle about the data's mean angle theta_c (the thesis saw wider loops where
the moment is larger).

Dataset section (paths relative to the dataset file)::

    [torque_angle]
    file = "torque_angle.csv"      # columns: angle_deg, torque_Nm, in time order
    # torque_sign = "spring"       # "spring" (default): torque_Nm is positive in the sense in which
    #                              #   the spring pushes the arm (what holds the arm against it);
    #                              # "applied": torque_Nm is the moment applied to the arm, CCW positive
    # angle_offset_deg = 0.0       # arm angle (deg, CCW from +x, pivot -> idler) = angle_offset_deg
    # angle_sense = "ccw"          #   + angle_deg ("ccw") or - angle_deg ("cw")
    # friction = "constant"        # or "linear": the band varies linearly with the angle
    # reversal_skip_deg = 1.0      # turning points are where the angle has come back by more than
    #                              #   this; the points within it of a turning point's angle, on
    #                              #   either side (the stick / pre-sliding part of the loop, and
    #                              #   samples that noise makes ambiguous), are left out. Default:
    #                              #   2 % of the angle range
    # direction_column = "dir"     # optional column of +1 / -1 (angle_deg increasing / decreasing,
    #                              #   0 = leave the point out) instead of the turning-point detection

Standard errors (1 sigma) are the least-squares ones, s^2 (X^T X)^-1 with the residual variance
s^2, inflated by sqrt((1 + rho) / (1 - rho)) when the residuals (in time order) have a positive
lag-one autocorrelation rho (an AR(1) effective sample size: stick-slip and sensor filtering make
neighbouring residuals alike); theta_0's error comes from k's and the intercept's by the delta
method.  ``friction_band_spread_Nm`` is the standard deviation of the local half-widths read from
ten angle bins (model-free: the loading and unloading residuals' difference in each bin), so a
band that is not constant shows there even with ``friction = "constant"``.

Every problem raises :class:`identification.data.DataError` with a one-line message naming the
key or file: missing columns, too few points, no reversal (the friction band cannot be told from
theta_0), an angle range too small for k, a negative k (wrong torque_sign), a loop running the
wrong way round (friction supplying energy).
"""

from __future__ import annotations

import json
import math
import pathlib
from dataclasses import dataclass, field

import numpy as np

from beltjax.tomltable import show
from identification.data import DataError, dataset_file, number, read_csv

__all__ = ["TorqueAngleFit", "fit_torque_angle", "branch_directions", "torque_model", "KEYS"]

#: keys accepted in the [torque_angle] section
KEYS = ("file", "torque_sign", "angle_offset_deg", "angle_sense", "friction", "reversal_skip_deg", "direction_column")
#: fewest rows in the file, and fewest used points on each branch
MIN_ROWS, MIN_BRANCH = 10, 3
#: smallest angle range (deg) over which k can be read at all
MIN_RANGE_DEG = 1.0
#: largest relative standard error of k (and of the band slope's effect) that counts as identified
MAX_REL_SE_K = 0.2
#: default turning-point threshold as a share of the angle range
DEFAULT_SKIP_SHARE = 0.02
#: angle bins for the model-free local half-widths
BAND_BINS = 10


# --------------------------------------------------------------------------- pure functions


def branch_directions(theta_deg: np.ndarray, threshold_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Branch of each sample of a loop in time order: (+1 rising, -1 falling, 0 unknown), and its
    margin: the angle (deg) from the nearer of the turning points that bound its branch.

    A turning point is confirmed once the angle has come back from its running extremum by more
    than ``threshold_deg`` (so noise smaller than that never flips the branch); samples before the
    first confirmed movement are 0.  Near a turning point the angle barely moves, so noise can
    put the recorded extremum a few samples late: samples with a small margin on either side of
    it are ambiguous (and in the stick / pre-sliding part of the loop).
    """
    th = np.asarray(theta_deg, dtype=float)
    n = th.size
    d = np.zeros(n, dtype=int)
    margin = np.zeros(n)
    pivots: list[tuple[int, int]] = []  # (index of the turning point, direction after it)
    trend, hi, lo = 0, 0, 0
    for i in range(1, n):
        if trend == 0:
            hi = i if th[i] > th[hi] else hi
            lo = i if th[i] < th[lo] else lo
            if th[i] - th[lo] > threshold_deg:
                trend, hi = 1, i
                pivots.append((lo, 1))
            elif th[hi] - th[i] > threshold_deg:
                trend, lo = -1, i
                pivots.append((hi, -1))
        elif trend == 1:
            if th[i] > th[hi]:
                hi = i
            elif th[hi] - th[i] > threshold_deg:
                trend, lo = -1, i
                pivots.append((hi, -1))
        else:
            if th[i] < th[lo]:
                lo = i
            elif th[i] - th[lo] > threshold_deg:
                trend, hi = 1, i
                pivots.append((lo, 1))
    for j, (p, s) in enumerate(pivots):
        end = pivots[j + 1][0] + 1 if j + 1 < len(pivots) else n
        seg = th[p + 1 : end]
        if seg.size == 0:
            continue
        d[p + 1 : end] = s
        last = seg.max() if s > 0 else seg.min()  # the next turning point (or the run's last extremum)
        margin[p + 1 : end] = np.minimum(np.abs(seg - th[p]), np.abs(last - seg))
    return d, margin


def _design(theta_rad: np.ndarray, d: np.ndarray, theta_c: float, linear: bool) -> np.ndarray:
    """Columns of T = b0 + b1 (theta - theta_c) + b2 (-d) [+ b3 (-d)(theta - theta_c)]."""
    x = theta_rad - theta_c
    cols = [np.ones_like(x), x, -d.astype(float)]
    if linear:
        cols.append(-d * x)
    return np.stack(cols, axis=1)


def torque_model(theta_deg, direction, k: float, theta0_deg: float, band: float, slope_per_deg: float = 0.0,
                 theta_c_deg: float = 0.0) -> np.ndarray:
    """Moment in the spring's sense (N m) at arm angles ``theta_deg`` (deg) on branch ``direction``
    (+1 rising, -1 falling): ``k (theta_0 - theta) - d (band + slope (theta - theta_c))``, k in
    N m/rad, band in N m, slope in N m/deg."""
    th = np.asarray(theta_deg, dtype=float)
    d = np.asarray(direction, dtype=float)
    spring = k * np.radians(theta0_deg - th)
    return spring - d * (band + slope_per_deg * (th - theta_c_deg))


def _lstsq(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Column-scaled least squares: (beta, covariance with s^2, residuals, AR(1) inflation)."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    beta_s, *_ = np.linalg.lstsq(Xs, y, rcond=None)
    beta = beta_s / scale
    r = y - X @ beta
    dof = max(X.shape[0] - X.shape[1], 1)
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(Xs.T @ Xs) / np.outer(scale, scale)
    rho = float(r[1:] @ r[:-1] / (r @ r)) if r @ r > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    return beta, cov, r, math.sqrt((1 + rho) / (1 - rho))


def _local_bands(theta_deg, d, r_spring, bins: int = BAND_BINS) -> np.ndarray:
    """Model-free local half-widths: rows (bin centre deg, half-width N m) where both branches
    have at least two points; r_spring = torque minus the fitted spring line."""
    lo, hi = float(np.min(theta_deg)), float(np.max(theta_deg))
    edges = np.linspace(lo, hi, bins + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        inside = (theta_deg >= a) & (theta_deg <= b)
        fall, rise = inside & (d < 0), inside & (d > 0)
        if fall.sum() >= 2 and rise.sum() >= 2:
            out.append(((a + b) / 2, (np.mean(r_spring[fall]) - np.mean(r_spring[rise])) / 2))
    return np.asarray(out).reshape(-1, 2)


def _fmt(v: float, se: float | None = None) -> str:
    """A value with as many digits as its standard error warrants (two significant in the error)."""
    if se is None or not (se > 0 and math.isfinite(se)):
        return f"{v:.6g}"
    digits = max(0, 1 - int(math.floor(math.log10(se))))
    return f"{v:.{digits}f} ± {se:.{digits}f}"


# --------------------------------------------------------------------------- result


@dataclass
class TorqueAngleFit:
    """Result of a torque–angle fit (units in the names; *_se are 1-sigma standard errors).

    Angles are arm angles (deg, CCW from +x); moments in the spring's sense (N m).  The arrays
    (angle, torque, direction, used) are the data as fitted, for plots.
    """

    key: str
    file: str
    friction: str
    torque_sign: str
    n_points: int
    n_used: int
    angle_range_deg: tuple[float, float]
    spring_stiffness_Nm_per_rad: float
    spring_stiffness_se: float
    spring_preload_deg: float
    spring_preload_se: float
    friction_band_Nm: float
    friction_band_se: float
    friction_band_at_deg: float
    friction_slope_Nm_per_deg: float | None
    friction_slope_se: float | None
    friction_band_spread_Nm: float
    friction_band_local: np.ndarray = field(repr=False)
    residual_rms_Nm: float = 0.0
    se_inflation: float = 1.0
    reversal_skip_deg: float = 0.0
    angle_deg: np.ndarray = field(default=None, repr=False)
    torque_Nm: np.ndarray = field(default=None, repr=False)
    direction: np.ndarray = field(default=None, repr=False)
    used: np.ndarray = field(default=None, repr=False)

    def predict(self, angle_deg, direction) -> np.ndarray:
        """Fitted moment in the spring's sense (N m) at arm angles (deg) on a branch (+1 / -1)."""
        return torque_model(
            angle_deg, direction, self.spring_stiffness_Nm_per_rad, self.spring_preload_deg, self.friction_band_Nm,
            self.friction_slope_Nm_per_deg or 0.0, self.friction_band_at_deg,
        )

    def to_json(self) -> dict:
        """JSON-ready summary (plain floats and lists)."""
        return dict(
            kind="torque_angle",
            key=self.key,
            file=self.file,
            model=f"T = k (theta_0 - theta) - d T_f{' (linear in theta)' if self.friction == 'linear' else ''}; "
            "T in the spring's sense, d = sign(dtheta/dt)",
            torque_sign=self.torque_sign,
            n_points=self.n_points,
            n_used=self.n_used,
            angle_range_deg=[float(a) for a in self.angle_range_deg],
            reversal_skip_deg=self.reversal_skip_deg,
            spring_stiffness_Nm_per_rad=self.spring_stiffness_Nm_per_rad,
            spring_stiffness_se_Nm_per_rad=self.spring_stiffness_se,
            spring_preload_deg=self.spring_preload_deg,
            spring_preload_se_deg=self.spring_preload_se,
            friction_band_Nm=self.friction_band_Nm,
            friction_band_se_Nm=self.friction_band_se,
            friction_band_at_deg=self.friction_band_at_deg,
            friction_slope_Nm_per_deg=self.friction_slope_Nm_per_deg,
            friction_slope_se_Nm_per_deg=self.friction_slope_se,
            friction_band_spread_Nm=self.friction_band_spread_Nm,
            friction_band_local=[[float(a), float(h)] for a, h in self.friction_band_local],
            residual_rms_Nm=self.residual_rms_Nm,
            se_inflation=self.se_inflation,
        )

    def table(self) -> str:
        """Plain-text table of the fitted parameters (1-sigma standard errors)."""
        rows = [
            ("spring stiffness k", _fmt(self.spring_stiffness_Nm_per_rad, self.spring_stiffness_se), "N m/rad"),
            ("free angle theta_0", _fmt(self.spring_preload_deg, self.spring_preload_se), "deg"),
            (f"friction band T_f (at {self.friction_band_at_deg:.1f} deg)",
             _fmt(self.friction_band_Nm, self.friction_band_se), "N m"),
        ]
        if self.friction_slope_Nm_per_deg is not None:
            slope = _fmt(self.friction_slope_Nm_per_deg, self.friction_slope_se)
            rows.append(("friction band slope", slope, "N m/deg"))
        rows += [
            ("band spread (10 angle bins)", f"{self.friction_band_spread_Nm:.3g}", "N m"),
            ("residual RMS", f"{self.residual_rms_Nm:.3g}", "N m"),
        ]
        w = max(len(r[0]) for r in rows)
        head = (f"torque-angle [{self.key}] {self.file}: {self.n_used} of {self.n_points} points, "
                f"arm angle {self.angle_range_deg[0]:.1f}-{self.angle_range_deg[1]:.1f} deg")
        return "\n".join([head] + [f"  {a:<{w}}  {b:>20}  {c}" for a, b, c in rows])

    def plot(self, out: pathlib.Path) -> list[pathlib.Path]:
        """Write ``<key>.png`` in directory ``out``: the loop (data by branch, points left out,
        fitted branches and spring line) and the local half-widths against the angle."""
        from beltjax.plotting import literal, save, subplots

        out = pathlib.Path(out)
        out.mkdir(parents=True, exist_ok=True)
        th, T, d, u = self.angle_deg, self.torque_Nm, self.direction, self.used
        fig, (ax, axb) = subplots(2, 1, figsize=(7.5, 7), height_ratios=[3, 1.3], sharex=True)
        ax.plot(th[u & (d < 0)], T[u & (d < 0)], ".", ms=3, color="C3", label="angle falling")
        ax.plot(th[u & (d > 0)], T[u & (d > 0)], ".", ms=3, color="C0", label="angle rising")
        if np.any(~u):
            ax.plot(th[~u], T[~u], "x", ms=3, color="0.6", label="left out (turning points)")
        grid = np.linspace(th[u].min(), th[u].max(), 200)
        ax.plot(grid, self.predict(grid, -1), "-", color="C3", lw=1.2)
        ax.plot(grid, self.predict(grid, +1), "-", color="C0", lw=1.2)
        ax.plot(grid, self.predict(grid, 0), "--", color="k", lw=1,
                label=f"spring: k = {self.spring_stiffness_Nm_per_rad:.4g} N m/rad, "
                f"theta_0 = {self.spring_preload_deg:.4g} deg")
        ax.set_ylabel("moment, spring's sense [N m]")
        ax.set_title(f"torque-angle loop ({literal(self.file, 80)})")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        loc = self.friction_band_local
        if loc.size:
            axb.plot(loc[:, 0], loc[:, 1], "o", color="C2", label="local half-width")
        band = self.friction_band_Nm + (self.friction_slope_Nm_per_deg or 0.0) * (grid - self.friction_band_at_deg)
        axb.plot(grid, band, "-", color="k", lw=1, label="fitted band T_f")
        axb.set_xlabel("arm angle [deg]")
        axb.set_ylabel("half-width [N m]")
        axb.legend(fontsize=8)
        axb.grid(alpha=0.3)
        path = out / f"{self.key.replace('.', '_')}.png"
        save(fig, path, dpi=110)
        return [path]

    def scene_block(self) -> str:
        """TOML ``[tensioner]`` fragment with the fitted spring and friction band (paste it into a
        scene and list the ``tensioner_friction`` effect)."""
        slope = ""
        if self.friction_slope_Nm_per_deg is not None:
            slope = f", varying by {self.friction_slope_Nm_per_deg:+.3g} N m/deg"
        return "\n".join([
            f"# from the torque-angle test {self.file} (1-sigma standard errors)",
            "[tensioner]",
            f"spring_stiffness = {self.spring_stiffness_Nm_per_rad:.6g}   # N m/rad, "
            f"± {self.spring_stiffness_se:.2g}",
            f"spring_preload_deg = {self.spring_preload_deg:.6g}   # deg, ± {self.spring_preload_se:.2g}",
            f"friction_moment = {self.friction_band_Nm:.6g}   # N m, ± {self.friction_band_se:.2g}: the dry-friction "
            f"band about the spring line at {self.friction_band_at_deg:.1f} deg{slope}",
            '# with "tensioner_friction" in [model] effects (regularised Coulomb at the pivot: beltjax.drive.pivot)',
        ])


# --------------------------------------------------------------------------- fit


def _choice(section: dict, name: str, key: str, options: tuple[str, ...]) -> str:
    v = section.get(name, options[0])
    if v not in options:
        raise DataError(f"must be one of {', '.join(map(repr, options))}, got {show(v)}", f"{key}.{name}")
    return v


def fit_torque_angle(section: dict, base: pathlib.Path, key: str = "torque_angle") -> TorqueAngleFit:
    """Fit k (N m/rad), theta_0 (deg) and the friction band (N m) to a torque–angle loop.

    ``section`` is the dataset's ``[torque_angle]`` table (keys in the module docstring), ``base``
    the folder its ``file`` is relative to.  Raises :class:`DataError` (one line) for bad data.
    """
    if not isinstance(section, dict):
        raise DataError("must be a table", key)
    unknown = [k for k in section if k not in KEYS]
    if unknown:
        raise DataError(f"unknown key (known: {', '.join(KEYS)})", f"{key}.{unknown[0]}")
    fname = section.get("file")
    if not isinstance(fname, str) or not fname:
        raise DataError("missing (a CSV file with columns angle_deg, torque_Nm)", f"{key}.file")
    path = dataset_file(base, fname, f"{key}.file")
    torque_sign = _choice(section, "torque_sign", key, ("spring", "applied"))
    sense = _choice(section, "angle_sense", key, ("ccw", "cw"))
    friction = _choice(section, "friction", key, ("constant", "linear"))
    offset = number(section, "angle_offset_deg", key, default=0.0)
    dcol = section.get("direction_column")
    if dcol is not None and (not isinstance(dcol, str) or not dcol):
        raise DataError(f"must be a column name, got {show(dcol)}", f"{key}.direction_column")
    columns = ["angle_deg", "torque_Nm"] + ([dcol] if dcol else [])
    data = read_csv(path, columns, f"{key} ({fname})", min_rows=MIN_ROWS)
    s = 1.0 if sense == "ccw" else -1.0
    theta = offset + s * data["angle_deg"]
    torque = data["torque_Nm"] if torque_sign == "spring" else -data["torque_Nm"]
    span = float(np.ptp(theta))
    if span < MIN_RANGE_DEG:
        raise DataError(f"{fname}: the angle spans only {span:.3g} deg (< {MIN_RANGE_DEG:g}): "
                        "spring_stiffness (k) is not identifiable; test over several degrees", key)
    skip = number(section, "reversal_skip_deg", key, default=DEFAULT_SKIP_SHARE * span)
    if skip < 0 or skip >= span / 2:
        raise DataError(f"must be >= 0 and below half the angle range ({span / 2:.3g} deg)", f"{key}.reversal_skip_deg")
    if dcol:
        raw = data[dcol]
        if not np.all(np.isin(raw, (-1.0, 0.0, 1.0))):
            raise DataError(f"column {show(dcol)} must hold only -1, 0 or +1", f"{key}.direction_column")
        d = (s * raw).astype(int)
        used = d != 0
    else:
        d, margin = branch_directions(theta, skip)
        used = (d != 0) & (margin >= skip)
    for sign, name in ((1, "rising"), (-1, "falling")):
        if np.sum(used & (d == sign)) < MIN_BRANCH:
            raise DataError(f"{fname}: fewer than {MIN_BRANCH} points with the angle {name} "
                            f"(after leaving out {skip:.3g} deg at each turning point): both loading and unloading "
                            "branches are needed, or the friction band and spring_preload_deg are not identifiable", key)
    th, T, dd = theta[used], torque[used], d[used]
    lin = friction == "linear"
    theta_c = float(np.mean(th))
    X = _design(np.radians(th), dd, math.radians(theta_c), lin)
    beta, cov, r, infl = _lstsq(X, T)
    cov = cov * infl**2
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    k, k_se = -beta[1], se[1]
    if not (k > 0 and k > 3 * k_se):
        hint = (" (torque_Nm looks like the applied moment: set torque_sign = \"applied\")"
                if k < -3 * k_se else "")
        raise DataError(f"{fname}: spring_stiffness (k) not identifiable: fitted {k:.4g} ± {k_se:.2g} N m/rad"
                        f"{hint}", key)
    if k_se > MAX_REL_SE_K * k:
        raise DataError(f"{fname}: spring_stiffness (k) not identifiable: {k:.4g} ± {k_se:.2g} N m/rad over "
                        f"{span:.3g} deg of angle; test over a wider angle range", key)
    band, band_se = beta[2], se[2]
    if band < -3 * band_se:
        raise DataError(f"{fname}: the loop runs the wrong way round (friction band {band:.3g} ± {band_se:.2g} "
                        "N m < 0: friction would supply energy): check the time order of the rows or torque_sign", key)
    theta0_rad = math.radians(theta_c) + beta[0] / k
    # delta method: theta_0 = theta_c + b0 / (-b1)
    g = np.zeros_like(beta)
    g[0], g[1] = 1.0 / k, beta[0] / k**2
    theta0_se = math.sqrt(max(float(g @ cov @ g), 0.0))
    slope = slope_se = None
    if lin:
        slope, slope_se = float(np.radians(beta[3])), float(np.radians(se[3]))  # N m/rad -> N m/deg
    r_spring = T - k * np.radians(math.degrees(theta0_rad) - th)
    local = _local_bands(th, dd, r_spring)
    spread = float(np.std(local[:, 1], ddof=1)) if local.shape[0] >= 2 else 0.0
    return TorqueAngleFit(
        key=key,
        file=fname,
        friction=friction,
        torque_sign=torque_sign,
        n_points=int(theta.size),
        n_used=int(used.sum()),
        angle_range_deg=(float(theta.min()), float(theta.max())),
        spring_stiffness_Nm_per_rad=float(k),
        spring_stiffness_se=float(k_se),
        spring_preload_deg=float(math.degrees(theta0_rad)),
        spring_preload_se=float(math.degrees(theta0_se)),
        friction_band_Nm=float(band),
        friction_band_se=float(band_se),
        friction_band_at_deg=theta_c,
        friction_slope_Nm_per_deg=slope,
        friction_slope_se=slope_se,
        friction_band_spread_Nm=spread,
        friction_band_local=local,
        residual_rms_Nm=float(np.sqrt(np.mean(r**2))),
        se_inflation=float(infl),
        reversal_skip_deg=float(skip),
        angle_deg=theta,
        torque_Nm=torque,
        direction=d,
        used=used,
    )


if __name__ == "__main__":  # pragma: no cover - a quick look: python -m identification.torque_angle DATA.toml
    import sys
    import tomllib

    p = pathlib.Path(sys.argv[1])
    fit = fit_torque_angle(tomllib.loads(p.read_text())["torque_angle"], p.parent)
    print(fit.table())
    print(fit.scene_block())
    print(json.dumps(fit.to_json(), indent=1)[:2000])
