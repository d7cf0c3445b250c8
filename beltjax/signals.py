"""Post-processing of uniformly sampled time histories (pure numpy): amplitude spectra, dominant
frequencies and per-channel summaries of transient belt-drive simulations.

Conventions: times in s, frequencies in Hz; signal values in any unit, and amplitudes and
summary statistics in the unit of the signal.  Summaries hold plain Python floats so that
they can be written to JSON as they are.
"""

from __future__ import annotations

import math

import numpy as np

MIN_SAMPLES = 8
UNIFORM_RTOL = 1e-6

_WINDOWS = {
    "hann": np.hanning,
    "hanning": np.hanning,
    "hamming": np.hamming,
    "blackman": np.blackman,
    "rect": np.ones,
    "rectangular": np.ones,
    "boxcar": np.ones,
    "none": np.ones,
}


def _check_time(t) -> tuple[np.ndarray, float]:
    """t as a float array and its (uniform) sample spacing (s); ValueError otherwise."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"time must be one-dimensional, got shape {t.shape}")
    if t.size < MIN_SAMPLES:
        raise ValueError(f"need at least {MIN_SAMPLES} samples for a spectrum, got {t.size}")
    if not np.all(np.isfinite(t)):
        raise ValueError("time has non-finite values")
    d = np.diff(t)
    dt = (t[-1] - t[0]) / (t.size - 1)
    if not dt > 0:
        raise ValueError("time must increase")
    dev = float(np.max(np.abs(d - dt)) / dt)
    if dev > UNIFORM_RTOL:
        raise ValueError(f"time is not uniformly sampled (relative spacing deviation {dev:.2e} > {UNIFORM_RTOL:g})")
    return t, float(dt)


def _detrended(t: np.ndarray, x: np.ndarray, detrend) -> np.ndarray:
    if detrend is False or detrend is None or detrend == "none":
        return x
    if detrend == "mean":
        return x - np.mean(x)
    if detrend is True or detrend == "linear":
        tc = t - np.mean(t)
        slope = np.dot(tc, x - np.mean(x)) / np.dot(tc, tc)
        return x - np.mean(x) - slope * tc
    raise ValueError(f"detrend must be True/'linear', 'mean' or False, got {detrend!r}")


def spectrum(t, x, *, detrend=True, window="hann"):
    """One-sided amplitude spectrum of a uniformly sampled signal.

    t: sample times (s), uniform, at least 8; x: samples (any unit), same length.
    detrend: True or "linear" removes the least-squares line, "mean" the mean, False nothing.
    window: "hann" (default), "hamming", "blackman" or "rect" (None: rect).
    Returns (f_hz, amplitude): frequencies (Hz), 0 .. Nyquist, and amplitudes in the unit
    of x, corrected for the window's coherent gain so that a sine of amplitude A centred
    on a frequency bin gives a peak of A (the DC bin gives the mean).
    """
    t, dt = _check_time(t)
    x = np.asarray(x, dtype=float)
    if x.shape != t.shape:
        raise ValueError(f"signal shape {x.shape} does not match time shape {t.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("signal has non-finite values")
    n = t.size
    key = "rect" if window is None else str(window).lower()
    if key not in _WINDOWS:
        raise ValueError(f"unknown window {window!r}; choose from {sorted(set(_WINDOWS))}")
    w = _WINDOWS[key](n)
    y = _detrended(t, x, detrend)
    amp = np.abs(np.fft.rfft(y * w)) / np.sum(w)
    if n % 2 == 0:
        amp[1:-1] *= 2.0  # the Nyquist bin has no mirror image
    else:
        amp[1:] *= 2.0
    return np.fft.rfftfreq(n, dt), amp


def dominant_frequencies(t, x, *, count=3, fmin=0.0, fmax=None, min_relative=0.05):
    """The largest distinct peaks of the amplitude spectrum (Hann window, linear detrend).

    t: uniform sample times (s); x: samples (any unit).  A peak is a local maximum of
    the spectrum with fmin <= f <= fmax (Hz; fmax None: Nyquist), refined by a parabola
    through the logarithms of the three amplitudes around it; peaks closer than 3 bins
    to a larger one, and peaks below min_relative x the largest, are dropped.
    Returns at most ``count`` (frequency_hz, amplitude) pairs (amplitude in the unit of x),
    largest amplitude first; an empty list for a signal without peaks.  For a single tone
    the frequency error is below 0.02 bin (1 bin = 1 / duration Hz) and the amplitude is
    exact on a bin and up to about 4 % high half-way between bins.
    """
    f, a = spectrum(t, x)
    df = float(f[1] - f[0])
    top = f[-1] if fmax is None else float(fmax)
    lo = float(fmin) if fmin is not None else 0.0
    inner = np.arange(1, a.size - 1)
    is_peak = (a[inner] > a[inner - 1]) & (a[inner] >= a[inner + 1]) & (f[inner] >= lo) & (f[inner] <= top)
    idx = inner[is_peak]
    if idx.size == 0 or count <= 0:
        return []
    idx = idx[np.argsort(-a[idx], kind="stable")]
    biggest = float(a[idx[0]])
    if not biggest > 0:
        return []
    tiny = biggest * 1e-30
    chosen: list[int] = []
    for i in idx:
        if a[i] < min_relative * biggest:
            break
        if all(abs(int(i) - j) >= 3 for j in chosen):
            chosen.append(int(i))
            if len(chosen) == count:
                break
    out = []
    for i in chosen:
        ym, y0, yp = np.log(a[i - 1] + tiny), np.log(a[i] + tiny), np.log(a[i + 1] + tiny)
        den = ym - 2.0 * y0 + yp
        p = 0.5 * (ym - yp) / den if den < 0 else 0.0
        p = float(np.clip(p, -0.5, 0.5))
        out.append((float((i + p) * df), float(np.exp(y0 - 0.25 * (ym - yp) * p))))
    out.sort(key=lambda fa: -fa[1])
    return out


def settled(t, settle_fraction=0.0) -> np.ndarray:
    """Boolean mask of the samples at or after settle_fraction of the record's duration.

    t: sample times (s), increasing; settle_fraction in [0, 1).  The last sample is always kept.
    """
    t = np.asarray(t, dtype=float)
    if not 0.0 <= settle_fraction < 1.0:
        raise ValueError(f"settle_fraction must be in [0, 1), got {settle_fraction}")
    if t.size == 0:
        return np.zeros(0, bool)
    span = float(t[-1] - t[0])
    keep = t >= t[0] + settle_fraction * span - 1e-12 * max(abs(span), 1e-300)
    keep[-1] = True
    return keep


def channel_summary(t, x, *, settle_fraction=0.0, count=3, fmin=None):
    """Statistics and dominant frequencies of one signal after its initial transient.

    t: sample times (s); x: samples (any unit), same length; settle_fraction: the leading
    fraction of the record's duration to ignore (0: the whole record).  fmin (Hz): lowest
    frequency of a dominant peak, default 2 / (duration kept), at least two periods.
    Returns a dict of plain floats: mean, min, max, peak_to_peak, rms_alternating (RMS about
    the mean), in the unit of x; dominant_hz (Hz) and dominant_amplitudes (unit of x),
    empty for a constant signal or one with fewer than 8 samples kept.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.ndim != 1 or x.shape != t.shape:
        raise ValueError(f"time shape {t.shape} and signal shape {x.shape} must be equal and 1-D")
    if t.size == 0:
        raise ValueError("empty record")
    if not np.all(np.isfinite(x)):
        raise ValueError("signal has non-finite values")
    keep = settled(t, settle_fraction)
    tk, xk = t[keep], x[keep]
    lo, hi = float(np.min(xk)), float(np.max(xk))
    ptp = hi - lo
    mean = float(np.mean(xk)) if ptp > 0 else lo  # no round-off for a constant signal
    rms = float(np.sqrt(np.mean((xk - mean) ** 2)))
    dom: list[tuple[float, float]] = []
    scale = float(np.max(np.abs(xk)))
    if tk.size >= MIN_SAMPLES and ptp > 1e-12 * scale and count > 0:
        duration = float(tk[-1] - tk[0])
        f_lo = 2.0 / duration if fmin is None else float(fmin)
        dom = [(fr, am) for fr, am in dominant_frequencies(tk, xk, count=count, fmin=f_lo)
               if math.isfinite(fr) and math.isfinite(am)]
    return {
        "mean": mean,
        "min": lo,
        "max": hi,
        "peak_to_peak": float(ptp),
        "rms_alternating": rms,
        "dominant_hz": [fr for fr, _ in dom],
        "dominant_amplitudes": [am for _, am in dom],
    }


def column_labels(name: str, shape: tuple, columns=None) -> list[str]:
    """Labels of the signals held in a channel of the given shape (nt,), (nt, k) or (nt, k, 2).

    1-D: [name]; 2-D: the k labels in columns[name] (default "0", "1", ...); 3-D with a
    last axis of 2 (x, y): "<col> x", "<col> y" for each column, in the order of
    ``x.reshape(nt, -1)``.
    """
    ndim = len(shape)
    if ndim == 1:
        return [name]
    if ndim not in (2, 3) or (ndim == 3 and shape[2] != 2):
        raise ValueError(f"channel {name!r}: shape {tuple(shape)} is not (nt,), (nt, k) or (nt, k, 2)")
    cols = list((columns or {}).get(name) or [str(j) for j in range(shape[1])])
    if len(cols) != shape[1]:
        raise ValueError(f"channel {name!r}: {len(cols)} column labels for {shape[1]} columns")
    if ndim == 2:
        return [str(c) for c in cols]
    return [f"{c} {ax}" for c in cols for ax in ("x", "y")]


def summarise(t, channels, columns, *, settle_fraction=0.0):
    """channel_summary of every signal of every channel.

    t: sample times (s), shape (nt,); channels: name -> array (nt,), (nt, k) or (nt, k, 2)
    (x, y components last); columns: name -> k column labels for the 2-D and 3-D channels.
    Returns {name: {label: channel_summary}}, the label being the channel name for a 1-D
    channel, the column label for a 2-D one and "<col> x" / "<col> y" for a 3-D one.
    Raises ValueError naming a channel with non-finite values or a wrong shape.
    """
    t = np.asarray(t, dtype=float)
    out: dict[str, dict[str, dict]] = {}
    for name, values in channels.items():
        arr = np.asarray(values, dtype=float)
        if arr.ndim == 0 or arr.shape[0] != t.shape[0]:
            raise ValueError(f"channel {name!r}: shape {arr.shape} does not start with the {t.shape[0]} time samples")
        labels = column_labels(name, arr.shape, columns)
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"channel {name!r} has non-finite values")
        flat = arr.reshape(arr.shape[0], -1)
        out[name] = {lab: channel_summary(t, flat[:, j], settle_fraction=settle_fraction)
                     for j, lab in enumerate(labels)}
    return out
