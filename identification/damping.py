"""Damping from impulse responses: modal frequencies and damping ratios of a decaying record.

A hammer blow (or a release) leaves a free decay, a sum of exponentially decaying sinusoids

    y(t) = c + sum_m exp(-sigma_m tau) (a_m cos(omega_m tau) + b_m sin(omega_m tau)),  tau = t - t_0,

with, per mode, the natural frequency ``f_n = sqrt(sigma^2 + omega^2) / (2 pi)`` (Hz, what a modal
analysis gives; the damped frequency ``omega / (2 pi)`` is reported too) and the damping ratio
``zeta = sigma / (2 pi f_n)``.  The fit:

1. an initial estimate by the matrix-pencil method (Hua & Sarkar 1990) on at most 1000 samples
   (box-car averaged and decimated when the record is longer: an FIR filter keeps the poles), of
   a model order above ``2 modes + 1`` so that noise has poles of its own; the ``modes``
   oscillating poles with the most energy are kept;
2. a Levenberg–Marquardt polish of all parameters (decays, frequencies, amplitudes, offset) on
   the whole record, with the Jacobian by ``jax.jacfwd`` (one jitted residual-and-Jacobian
   function per record shape);
3. standard errors (1 sigma) from the Gauss–Newton covariance ``s^2 (J^T J)^-1``, inflated by
   ``sqrt((1 + rho) / (1 - rho))`` for a positive lag-one autocorrelation rho of the residuals
   (AR(1) effective sample size), carried to f_n and zeta by the delta method.

Dataset section (paths relative to the dataset file)::

    [[impulse.record]]
    file = "hammer.csv"   # columns: time_s, response (any unit), uniformly sampled
    modes = 2             # number of decaying modes to fit (default 1)
    # name = "arm"        # label (default: the file name's stem)
    # t_start_s = 0.0     # fit from here on (skip the hammer contact)
    # t_end_s = 1.0       # fit up to here (default: the end of the record)
    # offset = true       # fit a constant offset c (default true; false: the response decays to 0)

A single record may also be given as ``[impulse]`` with ``file = ...`` directly.

Every problem raises :class:`identification.data.DataError` with a one-line message naming the
key or file: missing columns, an empty file, too few points, a time column that does not
increase or is not uniformly sampled, a constant response, fewer oscillating components than
``modes`` (no oscillation: a frequency and damping ratio are not identifiable), a mode that does
not decay measurably over the record (zeta within 3 standard errors of 0, or growing: damping
not identifiable), a mode whose amplitude is at the noise level.
"""

from __future__ import annotations

import json
import math
import pathlib
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import beltjax  # noqa: F401  (float64 in jax before any array is made)
from beltjax.tomltable import show
from identification.data import DataError, dataset_file, number, read_csv
from identification import least_squares
from identification.damping_result import ImpulseFit, RecordFit, _fmt, _safe, amplitude_spectrum  # noqa: F401

__all__ = [
    "ImpulseFit", "RecordFit", "fit_impulse", "fit_record", "decay_model", "matrix_pencil", "amplitude_spectrum",
    "RECORD_KEYS",
]

#: keys of one [[impulse.record]] table
RECORD_KEYS = ("file", "modes", "name", "t_start_s", "t_end_s", "offset")
#: most modes one record may ask for
MAX_MODES = 8
#: fewest samples in the fitted window, and per fitted parameter
MIN_POINTS, POINTS_PER_PARAMETER = 20, 5
#: largest relative deviation of a time step from the record's mean step
UNIFORM_RTOL = 0.01
#: samples the matrix pencil works on (decimated above this)
PENCIL_SAMPLES = 1000
#: extra pencil poles per mode for the noise
EXTRA_ORDER = 2
#: a mode must show at least this many cycles in the fitted window
MIN_CYCLES = 1.0
#: significance (in standard errors) of a mode's amplitude and of its decay
SIGNIFICANCE = 3.0
#: Levenberg-Marquardt (identification.least_squares): most steps, the Cauchy stop's relative and
#: absolute tolerances (on the Jacobi-scaled parameters and on each residual of the scaled record), and
#: the stop when the Gauss-Newton step could lower the cost by less than LM_GAIN of it
LM_ITERATIONS, LM_RTOL, LM_ATOL, LM_GAIN = 200, 1e-10, 1e-13, 1e-13


# --------------------------------------------------------------------------- pure functions


def decay_model(p: jax.Array, tau: jax.Array, modes: int, offset: bool) -> jax.Array:
    """Sum of decaying sinusoids at times ``tau`` (s from the window's start).

    p = [c (if offset), sigma_1..m (1/s), omega_1..m (rad/s), a_1..m, b_1..m] (response units).
    """
    c = p[0] if offset else 0.0
    q = p[1:] if offset else p
    sig, om, a, b = q[:modes], q[modes : 2 * modes], q[2 * modes : 3 * modes], q[3 * modes :]
    env = jnp.exp(-tau[:, None] * sig[None, :])
    ph = tau[:, None] * om[None, :]
    return c + jnp.sum(env * (a * jnp.cos(ph) + b * jnp.sin(ph)), axis=1)


@partial(jax.jit, static_argnames=("modes", "offset"))
def _residual_jacobian(p, tau, y, modes: int, offset: bool):
    r = lambda x: decay_model(x, tau, modes, offset) - y  # noqa: E731
    return r(p), jax.jacfwd(r)(p)


def matrix_pencil(y: np.ndarray, order: int) -> np.ndarray:
    """Discrete poles z_k (complex, ``order`` of them) of uniformly sampled y, by the matrix pencil."""
    n = y.size
    L = max(order + 1, n // 3)
    H = np.lib.stride_tricks.sliding_window_view(y, L + 1)  # (n - L, L + 1) Hankel
    _, _, Vh = np.linalg.svd(H, full_matrices=False)
    V = Vh[:order].conj().T
    return np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:])


def _linear_amplitudes(tau, y, sig, om, offset: bool):
    """Least-squares offset and cos/sin amplitudes for given decays and frequencies."""
    env = np.exp(-np.outer(tau, sig))
    ph = np.outer(tau, om)
    cols = ([np.ones_like(tau)[:, None]] if offset else []) + [env * np.cos(ph), env * np.sin(ph)]
    X = np.concatenate(cols, axis=1)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    return coef


def _pencil_guess(tau: np.ndarray, y: np.ndarray, dt: float, modes: int, offset: bool):
    """(sigma, omega) of the ``modes`` oscillating pencil poles with the most energy (units of tau);
    the number of oscillating poles found (an int, None for none) when fewer than ``modes``."""
    n = y.size
    q = max(1, math.ceil(n / PENCIL_SAMPLES))
    if q > 1:  # box-car average then decimate: the poles stay, noise and aliases fall
        yf = np.convolve(y, np.ones(q) / q, mode="valid")[::q][:PENCIL_SAMPLES]
    else:
        yf = y
    dtp = q * dt
    order = min(2 * modes + (1 if offset else 0) + 2 * EXTRA_ORDER * modes, yf.size // 3 - 1)
    z = matrix_pencil(yf - (yf.mean() if offset else 0.0), order)
    z = z[np.abs(z) > 1e-12]
    s = np.log(z.astype(complex)) / dtp
    n_win = yf.size
    # oscillating (half a cycle in the window, below Nyquist), not a noise pole growing 1000-fold
    osc = (s.imag > np.pi * MIN_CYCLES / (n_win * dtp)) & (s.imag < np.pi / dtp * 0.999)
    osc &= s.real * n_win * dtp < math.log(1e3)
    if not np.any(osc):
        return None
    # energy of every pole's component from a joint least-squares fit of all of them
    k = np.arange(n_win)
    Z = np.exp(np.outer(k * dtp, s))
    Z = np.concatenate([np.ones((n_win, 1)), Z], axis=1) if offset else Z
    h, *_ = np.linalg.lstsq(Z, yf.astype(complex), rcond=None)
    h = h[1:] if offset else h
    energy = np.abs(h) ** 2 * np.sum(np.abs(Z[:, -s.size :]) ** 2, axis=0)
    cand = np.flatnonzero(osc)
    cand = cand[np.argsort(-energy[cand])][:modes]
    if cand.size < modes:
        return cand.size
    return -s.real[cand], s.imag[cand]


def _residual(p, a):
    """Model less record (units of the scaled record), for the least-squares layer."""
    tau, y, modes, offset = a
    return decay_model(p, tau, modes, offset) - y


def _levenberg_marquardt(p, tau, y, modes: int, offset: bool):
    """Minimise |r(p)|^2 by the fits' least-squares layer (optimistix Levenberg-Marquardt,
    Jacobi-scaled at the start); returns (p, r, J) at the optimum."""
    tau_j, y_j = jnp.asarray(tau), jnp.asarray(y)
    _, J0 = _residual_jacobian(jnp.asarray(p), tau_j, y_j, modes, offset)
    sol = least_squares.solve(_residual, jnp.asarray(p), (tau_j, y_j, modes, offset), least_squares.column_scale(J0),
                              LM_ITERATIONS, history=LM_ITERATIONS, rtol=LM_RTOL, atol=LM_ATOL, gain_rtol=LM_GAIN)
    return np.asarray(sol.x), np.asarray(sol.residual), np.asarray(sol.jacobian)


# --------------------------------------------------------------------------- results


# --------------------------------------------------------------------------- fit


def _uniform_step(t: np.ndarray, key: str, fname: str) -> float:
    """The record's mean time step (s); DataError when time does not increase or is not uniform."""
    d = np.diff(t)
    bad = np.flatnonzero(d <= 0)
    if bad.size:
        i = int(bad[0])
        raise DataError(f"{fname}: time_s does not increase at data row {i + 2} "
                        f"({t[i]:.6g} s then {t[i + 1]:.6g} s)", key)
    dt = float((t[-1] - t[0]) / (t.size - 1))
    dev = float(np.max(np.abs(d - dt)) / dt)
    if dev > UNIFORM_RTOL:
        raise DataError(f"{fname}: time_s is not uniformly sampled (steps from {d.min():.4g} to {d.max():.4g} s, "
                        f"{100 * dev:.3g} % off the mean {dt:.4g} s); resample it to a constant step", key)
    return dt


def fit_record(t: np.ndarray, y: np.ndarray, modes: int = 1, *, offset: bool = True, key: str = "impulse",
               name: str = "record", fname: str = "<array>") -> RecordFit:
    """Fit ``modes`` decaying sinusoids to a uniformly sampled record (t in s, y in any unit).

    Returns a :class:`RecordFit` (natural frequencies in Hz, damping ratios, 1-sigma standard
    errors); raises :class:`DataError` (one line naming ``key`` and ``fname``) when the record
    cannot determine them.
    """
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    n_par = 4 * modes + (1 if offset else 0)
    need = max(MIN_POINTS, POINTS_PER_PARAMETER * n_par)
    if t.size < need:
        raise DataError(f"{fname}: {t.size} points in the fitted window; at least {need} are needed "
                        f"for {modes} mode(s)", key)
    dt = _uniform_step(t, key, fname)
    tau = t - t[0]
    T = float(tau[-1])
    scale = float(np.std(y)) if offset else float(np.sqrt(np.mean(y**2)))
    if not scale > 0 or scale <= 1e-12 * max(float(np.max(np.abs(y))), 1e-300):
        raise DataError(f"{fname}: the response is constant: no oscillation, nothing to fit", key)
    # work in units where the window lasts 1 and the response is O(1)
    ys, taus = y / scale, tau / T
    guess = _pencil_guess(taus, ys, dt / T, modes, offset)
    if not isinstance(guess, tuple):
        found = guess or 0
        raise DataError(f"{fname}: found {found} oscillating component(s) where modes = {modes} were asked: "
                        "no oscillation to fit, frequency and damping not identifiable "
                        "(lower modes or check the record)", key)
    sig, om = guess
    coef = _linear_amplitudes(taus, ys, sig, om, offset)
    p0 = np.concatenate(([coef[:1]] if offset else []) + [sig, om, coef[-2 * modes :]])
    p, r, J = _levenberg_marquardt(p0, taus, ys, modes, offset)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(r))):
        raise DataError(f"{fname}: the fit did not converge (non-finite parameters)", key)
    dof = max(ys.size - p.size, 1)
    s2 = float(r @ r) / dof
    rho = float(r[1:] @ r[:-1] / (r @ r)) if r @ r > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    infl = math.sqrt((1 + rho) / (1 - rho))
    try:
        cov = s2 * np.linalg.pinv(J.T @ J) * infl**2
    except np.linalg.LinAlgError:
        raise DataError(f"{fname}: the fit's covariance could not be formed (degenerate modes)", key) from None
    o = 1 if offset else 0
    idx_s, idx_w = o + np.arange(modes), o + modes + np.arange(modes)
    idx_a, idx_b = o + 2 * modes + np.arange(modes), o + 3 * modes + np.arange(modes)
    sig, om = p[idx_s] / T, p[idx_w] / T  # 1/s, rad/s
    flip = om < 0  # (omega, b) and (-omega, -b) are the same component
    om = np.abs(om)
    a_s, b_s = p[idx_a], np.where(flip, -p[idx_b], p[idx_b])
    wn = np.hypot(sig, om)
    fn, zeta = wn / (2 * np.pi), sig / np.maximum(wn, 1e-300)
    fn_se, zeta_se, amp, amp_se = (np.zeros(modes) for _ in range(4))
    for m in range(modes):
        i2 = [idx_s[m], idx_w[m]]
        C = cov[np.ix_(i2, i2)] / T**2
        g_f = np.array([sig[m], om[m]]) / (2 * np.pi * wn[m])
        g_z = np.array([om[m] ** 2, -sig[m] * om[m]]) / wn[m] ** 3
        if flip[m]:
            g_f[1], g_z[1] = -g_f[1], -g_z[1]
        fn_se[m] = math.sqrt(max(float(g_f @ C @ g_f), 0.0))
        zeta_se[m] = math.sqrt(max(float(g_z @ C @ g_z), 0.0))
        A = math.hypot(a_s[m], b_s[m])
        amp[m] = A * scale
        ia = [idx_a[m], idx_b[m]]
        g_a = np.array([p[idx_a[m]], p[idx_b[m]]]) / max(A, 1e-300)
        amp_se[m] = math.sqrt(max(float(g_a @ cov[np.ix_(ia, ia)] @ g_a), 0.0)) * scale
    for m in np.argsort(fn):
        where = f"{fname}: the mode at {fn[m]:.4g} Hz"
        cycles = om[m] / (2 * np.pi) * T
        if cycles < MIN_CYCLES or zeta[m] >= 0.9:
            raise DataError(f"{fname}: no oscillation (a fitted component makes {cycles:.2g} cycles in the "
                            f"window, zeta {zeta[m]:.2g}): frequency and damping not identifiable; lower modes "
                            "or check the record", key)
        if amp[m] < SIGNIFICANCE * amp_se[m]:
            raise DataError(f"{where} has an amplitude at the noise level ({amp[m]:.3g} ± {amp_se[m]:.2g}): "
                            f"the record shows fewer than modes = {modes} oscillating components", key)
        if zeta[m] < -SIGNIFICANCE * zeta_se[m]:
            raise DataError(f"{where} grows instead of decaying (zeta = {zeta[m]:.3g} ± {zeta_se[m]:.2g}): "
                            "damping not identifiable from this record", key)
        if zeta[m] < SIGNIFICANCE * zeta_se[m]:
            raise DataError(f"{where} shows no measurable decay (zeta = {zeta[m]:.3g} ± {zeta_se[m]:.2g}): "
                            "damping not identifiable (none, or too light for this record's length and noise)", key)
    order = np.argsort(fn)
    fitted = np.asarray(decay_model(jnp.asarray(p), jnp.asarray(taus), modes, offset)) * scale
    c = float(p[0] * scale) if offset else None
    resid = y - fitted
    dyn = y - (c or 0.0)
    return RecordFit(
        name=name,
        file=fname,
        modes=modes,
        n_points=int(t.size),
        t_window_s=(float(t[0]), float(t[-1])),
        sample_rate_hz=1.0 / dt,
        frequencies_hz=fn[order],
        frequencies_se_hz=fn_se[order],
        damped_frequencies_hz=(om / (2 * np.pi))[order],
        damping_ratios=zeta[order],
        damping_ratios_se=zeta_se[order],
        amplitudes=amp[order],
        offset=c,
        residual_rms_share=float(np.sqrt(np.mean(resid**2)) / max(np.sqrt(np.mean(dyn**2)), 1e-300)),
        se_inflation=infl,
        t=t,
        y=y,
        fitted=fitted,
    )


def _records(section: dict, key: str) -> list[tuple[str, dict]]:
    """(key of the record, its table) for ``[[key.record]]`` tables or a single ``[key]`` record."""
    if not isinstance(section, dict):
        raise DataError("must be a table", key)
    if "record" in section:
        extra = [k for k in section if k != "record"]
        if extra:
            raise DataError("unknown key next to [[record]] tables "
                            "(record keys go in each record)", f"{key}.{extra[0]}")
        recs = section["record"]
        if isinstance(recs, dict):
            recs = [recs]
        if not isinstance(recs, list) or not recs or not all(isinstance(r, dict) for r in recs):
            raise DataError("must be one or more [[record]] tables", f"{key}.record")
        return [(f"{key}.record[{i}]", r) for i, r in enumerate(recs)]
    if "file" in section:
        return [(key, section)]
    raise DataError("needs [[impulse.record]] tables (file = ..., modes = ...)", key)


def fit_impulse(section: dict, base: pathlib.Path, key: str = "impulse") -> ImpulseFit:
    """Fit every record of an ``[impulse]`` section (keys in the module docstring); CSV paths are
    relative to ``base``.  Returns an :class:`ImpulseFit`; raises :class:`DataError` (one line)."""
    fits, plotted = [], {}
    for rkey, rec in _records(section, key):
        unknown = [k for k in rec if k not in RECORD_KEYS]
        if unknown:
            raise DataError(f"unknown key (known: {', '.join(RECORD_KEYS)})", f"{rkey}.{unknown[0]}")
        fname = rec.get("file")
        if not isinstance(fname, str) or not fname:
            raise DataError("missing (a CSV file with columns time_s, response)", f"{rkey}.file")
        modes = rec.get("modes", 1)
        if isinstance(modes, bool) or not isinstance(modes, int) or not 1 <= modes <= MAX_MODES:
            raise DataError(f"must be a whole number from 1 to {MAX_MODES}, got {show(modes)}", f"{rkey}.modes")
        offset = rec.get("offset", True)
        if not isinstance(offset, bool):
            raise DataError(f"must be true or false, got {show(offset)}", f"{rkey}.offset")
        name = rec.get("name", pathlib.Path(fname).stem)
        if not isinstance(name, str) or not name:
            raise DataError(f"must be a non-empty string, got {show(name)}", f"{rkey}.name")
        if _safe(name) in plotted:  # the record's plot file would overwrite the other's
            raise DataError(f"record name {show(name)} is taken by {plotted[_safe(name)]} (its plot is named by "
                            "it; a name defaults to the file's stem): give each record its own name", f"{rkey}.{'name' if 'name' in rec else 'file'}")
        plotted[_safe(name)] = rkey
        data = read_csv(dataset_file(base, fname, f"{rkey}.file"), ["time_s", "response"], f"{rkey} ({fname})")
        t, y = data["time_s"], data["response"]
        t0 = number(rec, "t_start_s", rkey) if "t_start_s" in rec else float(t[0])
        t1 = number(rec, "t_end_s", rkey) if "t_end_s" in rec else float(t[-1])
        if t1 <= t0:
            raise DataError(f"must be after t_start_s ({t0:.6g} s), got {t1:.6g} s", f"{rkey}.t_end_s")
        _uniform_step(t, rkey, fname)
        keep = (t >= t0 - 1e-12) & (t <= t1 + 1e-12)
        fits.append(fit_record(t[keep], y[keep], modes, offset=offset, key=rkey, name=name, fname=fname))
    return ImpulseFit(key=key, records=fits)


if __name__ == "__main__":  # pragma: no cover - a quick look: python -m identification.damping DATA.toml
    import sys
    import tomllib

    path = pathlib.Path(sys.argv[1])
    res = fit_impulse(tomllib.loads(path.read_text())["impulse"], path.parent)
    print(res.table())
    print(res.scene_block())
    print(json.dumps(res.to_json(), indent=1)[:3000])
