"""The result of an impulse fit: per record the modal frequencies (Hz), damping ratios and amplitudes
with standard errors (:class:`RecordFit`), the report, fit.json and the plots (:class:`ImpulseFit`);
the amplitude spectrum they draw."""

from __future__ import annotations

import math
import pathlib
from dataclasses import dataclass, field

import numpy as np


def amplitude_spectrum(y: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided amplitude spectrum (Hann window, mean removed): (frequencies Hz, amplitude in y's unit)."""
    y = np.asarray(y, dtype=float)
    w = np.hanning(y.size)
    Y = np.fft.rfft((y - y.mean()) * w)
    return np.fft.rfftfreq(y.size, dt), 2.0 * np.abs(Y) / np.sum(w)


@dataclass
class RecordFit:
    """Fit of one record.  Per mode (ascending f_n): natural and damped frequencies (Hz),
    damping ratios, their 1-sigma standard errors, amplitudes at the window's start (response
    units).  The arrays t, y, fitted are the window as fitted, for plots."""

    name: str
    file: str
    modes: int
    n_points: int
    t_window_s: tuple[float, float]
    sample_rate_hz: float
    frequencies_hz: np.ndarray
    frequencies_se_hz: np.ndarray
    damped_frequencies_hz: np.ndarray
    damping_ratios: np.ndarray
    damping_ratios_se: np.ndarray
    amplitudes: np.ndarray
    offset: float | None
    residual_rms_share: float
    se_inflation: float
    t: np.ndarray = field(repr=False, default=None)
    y: np.ndarray = field(repr=False, default=None)
    fitted: np.ndarray = field(repr=False, default=None)

    def to_json(self) -> dict:
        """JSON-ready summary of the record's fit."""
        fl = lambda a: [float(x) for x in a]  # noqa: E731
        return dict(
            name=self.name,
            file=self.file,
            modes=self.modes,
            n_points=self.n_points,
            t_window_s=fl(self.t_window_s),
            sample_rate_hz=self.sample_rate_hz,
            frequencies_hz=fl(self.frequencies_hz),
            frequencies_se_hz=fl(self.frequencies_se_hz),
            damped_frequencies_hz=fl(self.damped_frequencies_hz),
            damping_ratios=fl(self.damping_ratios),
            damping_ratios_se=fl(self.damping_ratios_se),
            amplitudes=fl(self.amplitudes),
            offset=self.offset,
            residual_rms_share=self.residual_rms_share,
            se_inflation=self.se_inflation,
        )


def _fmt(v: float, se: float) -> str:
    if not (se > 0 and math.isfinite(se)):
        return f"{v:.6g}"
    digits = max(0, 1 - int(math.floor(math.log10(se))))
    return f"{v:.{digits}f} ± {se:.{digits}f}"


@dataclass
class ImpulseFit:
    """Fits of all records of an ``[impulse]`` section."""

    key: str
    records: list[RecordFit]

    def to_json(self) -> dict:
        """JSON-ready summary: per record, frequencies_hz, damping_ratios, their standard errors,
        residual RMS share."""
        return dict(
            kind="impulse",
            key=self.key,
            model="y = c + sum exp(-sigma t) (a cos(omega t) + b sin(omega t)); f_n = |sigma + i omega| / 2 pi, "
            "zeta = sigma / (2 pi f_n)",
            records=[r.to_json() for r in self.records],
        )

    def table(self) -> str:
        """Plain-text table: one row per mode (1-sigma standard errors)."""
        lines = [f"impulse responses [{self.key}]: {len(self.records)} record(s)",
                 f"  {'record':<14} {'mode':>4}  {'f_n [Hz]':>18}  {'zeta [%]':>16}  {'residual':>8}"]
        for r in self.records:
            for m in range(r.modes):
                lines.append(
                    f"  {r.name:<14} {m + 1:>4}  {_fmt(r.frequencies_hz[m], r.frequencies_se_hz[m]):>18}  "
                    f"{_fmt(100 * r.damping_ratios[m], 100 * r.damping_ratios_se[m]):>16}  "
                    f"{100 * r.residual_rms_share:>7.3g}%"
                )
        return "\n".join(lines)

    def plot(self, out: pathlib.Path) -> list[pathlib.Path]:
        """Write ``<key>_<record>.png`` per record in directory ``out``: data and fit against time,
        and their amplitude spectra with the fitted natural frequencies."""
        from beltjax.plotting import literal, save, subplots

        out = pathlib.Path(out)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for r in self.records:
            fig, (ax, axs) = subplots(2, 1, figsize=(8, 7))
            c = r.offset or 0.0
            ax.plot(r.t, r.y - c, "-", lw=0.8, color="0.5", label="data")
            label = f"fit ({r.modes} mode{'s' if r.modes > 1 else ''})"
            ax.plot(r.t, r.fitted - c, "-", lw=0.9, color="C3", label=label)
            ax.plot(r.t, r.y - r.fitted, "-", lw=0.6, color="C0", alpha=0.8, label="residual")
            ax.set_xlabel("time [s]")
            ax.set_ylabel(f"response - offset ({c:.6g})" if r.offset is not None else "response")
            ax.set_title(f"{literal(r.name, 60)} ({literal(r.file, 60)})")
            ax.legend(fontsize=8)
            ax.grid(alpha=0.3)
            dt = 1.0 / r.sample_rate_hz
            f, A = amplitude_spectrum(r.y, dt)
            _, Af = amplitude_spectrum(r.fitted, dt)
            axs.semilogy(f, np.maximum(A, 1e-300), "-", lw=0.8, color="0.5", label="data")
            axs.semilogy(f, np.maximum(Af, 1e-300), "-", lw=0.9, color="C3", label="fit")
            for fn, z in zip(r.frequencies_hz, r.damping_ratios):
                axs.axvline(fn, color="C2", lw=0.8, ls="--")
                axs.annotate(f"{fn:.4g} Hz\nzeta {100 * z:.3g} %", (fn, np.max(A)), fontsize=7, ha="left", va="top")
            fmax = min(f[-1], 3 * float(np.max(r.frequencies_hz)))
            axs.set_xlim(0, fmax)
            positive = A[(f > 0) & (f <= fmax)]
            if positive.size:
                axs.set_ylim(max(positive.min(), positive.max() * 1e-6) / 2, positive.max() * 3)
            axs.set_xlabel("frequency [Hz]")
            axs.set_ylabel("amplitude (Hann)")
            axs.legend(fontsize=8)
            axs.grid(alpha=0.3, which="both")
            path = out / f"{self.key.replace('.', '_')}_{_safe(r.name)}.png"
            save(fig, path, dpi=110)
            paths.append(path)
        return paths

    def scene_block(self) -> str:
        """A TOML comment block: the fitted modes and what they mean for the scene's damping keys."""
        lines = ["# Damping from impulse responses (1-sigma standard errors).  The scene has no modal damping",
                 "# key: its damping is physical (belt.CA, tensioner.damping, pulley bearing_damping).  Per mode:",
                 "#  * a single-inertia mode (e.g. the tensioner arm swinging on its spring) has",
                 "#    c = 2 zeta omega_n J, so tensioner.damping = (2 zeta omega_n) x J_eff (arm + idler",
                 "#    inertia about the pivot, kg m^2);",
                 "#  * a mode that stretches the spans (a torsional mode) has Kelvin-Voigt damping",
                 "#    zeta = pi f_n CA / EA, so belt.CA = zeta EA / (pi f_n) = (zeta / (pi f_n)) x EA."]
        for r in self.records:
            for m in range(r.modes):
                f, z = r.frequencies_hz[m], r.damping_ratios[m]
                lines.append(
                    f"# {r.name} mode {m + 1}: f_n = {_fmt(f, r.frequencies_se_hz[m])} Hz, zeta = "
                    f"{_fmt(z, r.damping_ratios_se[m])}: 2 zeta omega_n = {4 * math.pi * f * z:.4g} 1/s, "
                    f"zeta / (pi f_n) = {z / (math.pi * f):.4g} s"
                )
        return "\n".join(lines)


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
