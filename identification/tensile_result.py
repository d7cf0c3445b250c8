"""The result of a tensile fit (:class:`TensileFit`): G(f), EA(f), DA(f) and CA(f) with their bands,
the report, fit.json, the scene block to paste (EA in N, CA in N s at a chosen frequency) and the
plots."""

from __future__ import annotations

import math
import pathlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from identification.tensile_model import evaluate

if TYPE_CHECKING:  # (tensile imports this module)
    from identification.tensile import Record


#: two-sided confidence level of the EA / DA bands
BAND_LEVEL = 0.95


#: frequencies always present in the EA / DA tables (Hz; Table 6.2's columns and the 10 Hz scene default)
REPORT_FREQUENCIES_HZ = (0.01, 10.0, 60.0)


#: reduced chi^2 above which the result carries a warning
CHI2_WARN = 4.0


#: default frequency of the scene block (Hz)
SCENE_FREQUENCY_HZ = 10.0


#: frequencies of the EA / CA rows listed in the scene block's comment (Hz), besides the chosen one
BLOCK_FREQUENCIES_HZ = (1.0, 10.0, 30.0, 100.0, 300.0)


PARAMETER_NAMES = ("Re a1", "Im a1", "Re a2", "Im a2", "Re b1", "Im b1", "Re b2", "Im b2")


def _fkey(f: float) -> str:
    """Table key of a frequency: "0.01", "10", "60"."""
    return f"{f:g}"


def _complex_pair(z: complex) -> list[float]:
    return [float(z.real), float(z.imag)]


@dataclass
class TensileFit:
    """Result of :func:`fit_tensile` (G in N/mm, f in Hz, EA and DA in N, CA in N s)."""

    key: str
    specimen_length_m: float
    scene_frequency_hz: float
    records: list[Record]
    theta: np.ndarray              # (Re a1, Im a1, Re a2, Im a2, Re b1, Im b1, Re b2, Im b2)
    covariance: np.ndarray         # 8 x 8
    chi2: float
    dof: int
    covariance_scale: float
    loss_history: list[float]      # L-BFGS then LM, of the winning start (chi^2 / 2)
    lbfgs_steps: int
    starts: int
    start_losses: list[float]      # final chi^2 / 2 of every start
    source: str = ""

    # ----- model evaluation

    @property
    def std_errors(self) -> np.ndarray:
        """Standard errors of the 8 real parameters (units of Table 6.1)."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the 8 real parameters."""
        se = self.std_errors
        return self.covariance / np.outer(se, se)

    @property
    def length_mm(self) -> float:
        return 1000.0 * self.specimen_length_m

    def modulus(self, f) -> np.ndarray:
        """Model G(f) (complex, N/mm) at frequencies f (Hz)."""
        return evaluate(self.theta, f)[0]

    def EA(self, f) -> tuple[np.ndarray, np.ndarray]:
        """EA(f) = Re G(f) L (N) and its standard error (delta method) at f (Hz)."""
        G, J = evaluate(self.theta, f)
        g = J.real * self.length_mm
        return G.real * self.length_mm, np.sqrt(np.einsum("ni,ij,nj->n", g, self.covariance, g))

    def DA(self, f) -> tuple[np.ndarray, np.ndarray]:
        """DA(f) = |Im G(f)| L (N) and its standard error (delta method) at f (Hz)."""
        G, J = evaluate(self.theta, f)
        g = (np.sign(G.imag)[:, None] * J.imag) * self.length_mm
        return np.abs(G.imag) * self.length_mm, np.sqrt(np.einsum("ni,ij,nj->n", g, self.covariance, g))

    def CA(self, f) -> np.ndarray:
        """Viscous equivalent CA(f) = DA(f) / (2 pi f) (N s) at f (Hz)."""
        f = np.atleast_1d(np.asarray(f, dtype=np.float64))
        return self.DA(f)[0] / (2.0 * math.pi * f)

    @property
    def table_frequencies(self) -> list[float]:
        """0.01, 10, 60 Hz, the scene frequency and every tested frequency, ascending."""
        fs = set(REPORT_FREQUENCIES_HZ) | {self.scene_frequency_hz} | {r.frequency_hz for r in self.records}
        return sorted(fs)

    @property
    def tested_range_hz(self) -> tuple[float, float]:
        fs = [r.frequency_hz for r in self.records]
        return min(fs), max(fs)

    def band_grid(self, n: int = 200) -> np.ndarray:
        """Log-spaced frequencies (Hz) covering the tested range and the report frequencies."""
        lo = min(self.tested_range_hz[0], min(REPORT_FREQUENCIES_HZ))
        hi = max(self.tested_range_hz[1], max(REPORT_FREQUENCIES_HZ))
        return np.logspace(math.log10(lo), math.log10(hi), n)

    @property
    def z_band(self) -> float:
        """Normal quantile of the two-sided ``BAND_LEVEL`` band."""
        from statistics import NormalDist

        return NormalDist().inv_cdf(0.5 + 0.5 * BAND_LEVEL)

    @property
    def warnings(self) -> list[str]:
        """Notes on the fit's quality (empty when chi^2 is consistent with the records' scatter)."""
        out = []
        if self.dof > 0 and self.chi2 / self.dof > CHI2_WARN:
            out.append(f"the power-sum model does not reach the records' scatter (chi2/dof = {self.chi2 / self.dof:.3g}); "
                       f"standard errors are scaled by sqrt({self.covariance_scale:.3g})")
        a2, se = math.hypot(self.theta[2], self.theta[3]), self.std_errors
        if a2 < 2.0 * math.hypot(se[2], se[3]) / math.sqrt(2.0):
            out.append(f"the second power term is not significant (|a2| = {a2:.3g} N/mm, sigma "
                       f"{math.hypot(se[2], se[3]) / math.sqrt(2.0):.2g}): b2 is poorly determined and a single "
                       "power law would do")
        if self.dof == 0:
            out.append("4 records for 8 real parameters: the fit is exact and its standard errors rest on the "
                       "records' own uncertainties only")
        return out

    # ----- records

    def record_rows(self) -> list[dict]:
        """Per record: file, frequency, G (N/mm) with its sigma, model G, normalised residual."""
        f = np.array([r.frequency_hz for r in self.records])
        Gm = self.modulus(f)
        rows = []
        for r, gm in zip(self.records, Gm):
            d = gm - r.G
            L = np.linalg.cholesky(r.covariance)
            w = np.linalg.solve(L, [d.real, d.imag])
            rows.append({
                "key": r.key, "file": r.file, "frequency_hz": r.frequency_hz, "samples": r.samples,
                "cycles": r.cycles,
                "G_N_per_mm": _complex_pair(r.G),
                "G_std_N_per_mm": [float(np.sqrt(r.covariance[0, 0])), float(np.sqrt(r.covariance[1, 1]))],
                "G_model_N_per_mm": _complex_pair(complex(gm)),
                "residual_N_per_mm": _complex_pair(complex(d)),
                "normalised_residual": [float(w[0]), float(w[1])],
                "displacement_amplitude_m": abs(r.displacement.amplitude),
                "force_amplitude_N": abs(r.force.amplitude),
                "mean_force_N": r.force.mean,
                "sine_fit_residual_share": {"displacement": r.displacement.residual_share,
                                            "force": r.force.residual_share},
            })
        return rows

    # ----- outputs

    def to_json(self) -> dict:
        """fit.json contents of the tensile section."""
        th, se = self.theta, self.std_errors
        fs = self.table_frequencies
        ea, ea_se = self.EA(fs)
        da, da_se = self.DA(fs)
        grid = self.band_grid()
        g_ea, g_ea_se = self.EA(grid)
        g_da, g_da_se = self.DA(grid)
        z = self.z_band
        lo, hi = self.tested_range_hz
        model = {
            "model": "G(f) = a1*f**b1 + a2*f**b2, f in Hz, G in N/mm (specimen length L in mm); "
                     "f**b = exp(b ln f); Im G < 0 for a dissipative specimen (Table 6.1's convention)",
            "units": "a1, a2 in N/mm, b1, b2 dimensionless (as Table 6.1); [real, imag]",
            "a1": [th[0], th[1]], "a2": [th[2], th[3]], "b1": [th[4], th[5]], "b2": [th[6], th[7]],
            "std_errors": {"a1": [se[0], se[1]], "a2": [se[2], se[3]], "b1": [se[4], se[5]], "b2": [se[6], se[7]]},
            "parameter_order": list(PARAMETER_NAMES),
            "correlation": np.round(self.correlation, 6).tolist(),
        }
        return {
            "dataset": self.source,
            "specimen_length_m": self.specimen_length_m,
            "records": len(self.records),
            "tested_frequency_range_hz": [lo, hi],
            "power_sum_model": {k: _tolist(v) for k, v in model.items()},
            "EA_N": {_fkey(f): float(v) for f, v in zip(fs, ea)},
            "EA_std_N": {_fkey(f): float(v) for f, v in zip(fs, ea_se)},
            "DA_N": {_fkey(f): float(v) for f, v in zip(fs, da)},
            "DA_std_N": {_fkey(f): float(v) for f, v in zip(fs, da_se)},
            "CA_Ns": {_fkey(f): float(v) for f, v in zip(fs, da / (2 * math.pi * np.asarray(fs)))},
            "extrapolated_hz": [_fkey(f) for f in fs if f < lo * (1 - 1e-12) or f > hi * (1 + 1e-12)],
            "bands": {
                "level": BAND_LEVEL, "method": "delta method on the 8-parameter covariance",
                "frequency_hz": grid.tolist(),
                "EA_N": g_ea.tolist(), "EA_lower_N": (g_ea - z * g_ea_se).tolist(),
                "EA_upper_N": (g_ea + z * g_ea_se).tolist(),
                "DA_N": g_da.tolist(), "DA_lower_N": (g_da - z * g_da_se).tolist(),
                "DA_upper_N": (g_da + z * g_da_se).tolist(),
            },
            "per_record": self.record_rows(),
            "chi2": self.chi2, "dof": self.dof,
            "reduced_chi2": self.chi2 / self.dof if self.dof > 0 else None,
            "covariance_scale": self.covariance_scale,
            "warnings": self.warnings,
            "optimizer": f"optax.lbfgs ({self.lbfgs_steps} steps) then optimistix Levenberg-Marquardt, "
                         f"{self.starts} deterministic starts",
            "loss_history_length": len(self.loss_history),
            "final_loss": float(self.loss_history[-1]),
            "loss_history": [float(v) for v in self.loss_history],
            "start_final_losses": [float(v) for v in self.start_losses],
            "scene_frequency_hz": self.scene_frequency_hz,
            "scene_block": self.scene_block(),
        }

    def table(self) -> str:
        """Power-sum parameters, EA / DA at the table frequencies and per-record residuals as text."""
        th, se = self.theta, self.std_errors
        out = [f"tensile test: {len(self.records)} records, L = {self.length_mm:.4g} mm, "
               f"chi2/dof = {self.chi2:.4g}/{self.dof}"]
        for i, n in enumerate(("a1", "a2", "b1", "b2")):
            out.append(f"  {n} = {th[2 * i]:.6g} {'-' if th[2 * i + 1] < 0 else '+'} i {abs(th[2 * i + 1]):.6g}"
                       f"    (+- {se[2 * i]:.2g}, {se[2 * i + 1]:.2g})")
        fs = self.table_frequencies
        ea, ea_se = self.EA(fs)
        da, da_se = self.DA(fs)
        out.append(f"{'f [Hz]':>9} {'EA [N]':>10} {'+-':>7} {'DA [N]':>9} {'+-':>7} {'CA [N s]':>9}  record G [N/mm]")
        rec = {}
        for r in self.records:
            rec.setdefault(r.frequency_hz, []).append(r.G)
        for f, e, es, d, ds in zip(fs, ea, ea_se, da, da_se):
            g = "  ".join(f"{z.real:.5g}{z.imag:+.4g}i" for z in rec.get(f, []))
            out.append(f"{f:>9g} {e:>10.6g} {es:>7.2g} {d:>9.5g} {ds:>7.2g} {d / (2 * math.pi * f):>9.4g}  {g}")
        out += [f"warning: {w}" for w in self.warnings]
        return "\n".join(out)

    def scene_block(self) -> str:
        """A ``[belt]`` fragment: EA and the viscous CA = DA / (2 pi f) at the scene frequency
        (``scene_frequency_hz``, N and N s), saying which frequency that is, with a comment
        table of EA and CA at 1, 10, 30, 100 and 300 Hz (CA falls about as 1/f, so a value for
        10 Hz is ten times too large for a drive whose modes are near 100 Hz)."""
        f = self.scene_frequency_hz
        ea, ea_se = self.EA([f])
        da, _ = self.DA([f])
        ca = da[0] / (2 * math.pi * f)
        src = f" of {self.source}" if self.source else ""
        lo, hi = self.tested_range_hz
        fs = sorted(set(BLOCK_FREQUENCIES_HZ) | {f})
        eas, _ = self.EA(fs)
        cas = self.CA(fs)
        ratio = float(self.CA([10.0])[0] / self.CA([100.0])[0])
        rows = [f"#   {x:>8g} {e:>12.6g} {c:>10.4g}" + ("   <- below" if x == f else "")
                + ("   (extrapolated: tested %g-%g Hz)" % (lo, hi) if x < lo * (1 - 1e-12) or x > hi * (1 + 1e-12)
                   else "")
                for x, e, c in zip(fs, eas, cas)]
        return "\n".join([
            f"# tensile test{src}: power-sum complex modulus, L = {self.length_mm:.4g} mm",
            f"# EA and CA below are for f = {f:g} Hz: [tensile] scene_frequency_hz of the dataset (default "
            f"{SCENE_FREQUENCY_HZ:g} Hz);",
            "# set it to the frequency of the drive's modes of interest.  CA = DA / (2 pi f) is the viscous",
            f"# equivalent of the belt's damping at one frequency and falls steeply with it (here CA(10 Hz) / "
            f"CA(100 Hz) = {ratio:.3g}):",
            f"#   {'f [Hz]':>8} {'EA [N]':>12} {'CA [N s]':>10}",
            *rows,
            "# CA needs \"belt_damping\" in model.effects.",
            "[belt]",
            f"EA = {ea[0]:.6g}    # N at {f:g} Hz, +- {ea_se[0]:.2g} (1 sigma)",
            f"CA = {ca:.6g}    # N s at {f:g} Hz (DA = {da[0]:.5g} N)",
        ])

    def plot(self, out: pathlib.Path) -> list[pathlib.Path]:
        """tensile_modulus.png (|G| and phase vs f with data, model and band) and tensile_loss.png."""
        from beltjax.plotting import literal, save, subplots

        out = pathlib.Path(out)
        out.mkdir(parents=True, exist_ok=True)
        grid = self.band_grid()
        G, J = evaluate(self.theta, grid)
        mag = np.abs(G)
        ph = np.degrees(np.angle(G))
        # delta-method sigmas of |G| and phase
        u = np.conj(G) / np.where(mag > 0, mag, 1.0)
        g_mag = (u[:, None] * J).real
        g_ph = np.degrees((np.conj(G)[:, None] * J).imag / np.where(mag > 0, mag**2, 1.0)[:, None])
        s_mag = np.sqrt(np.einsum("ni,ij,nj->n", g_mag, self.covariance, g_mag))
        s_ph = np.sqrt(np.einsum("ni,ij,nj->n", g_ph, self.covariance, g_ph))
        z = self.z_band
        f = np.array([r.frequency_hz for r in self.records])
        Gd = np.array([r.G for r in self.records])
        sd = np.array([r.sigma for r in self.records])
        fig, (a1, a2) = subplots(2, 1, figsize=(6.5, 6), sharex=True)
        a1.fill_between(grid, mag - z * s_mag, mag + z * s_mag, color="C0", alpha=0.25,
                        label=f"{100 * BAND_LEVEL:.0f} % band")
        a1.plot(grid, mag, color="C0", label="power-sum model")
        a1.errorbar(f, np.abs(Gd), yerr=z * sd, fmt="o", ms=4, color="k", capsize=2, label="records")
        a1.set_xscale("log")
        a1.set_ylabel("|G| [N/mm]")
        a1.set_title(f"Tensile test{': ' + literal(self.source, 80) if self.source else ''} "
                     f"(L = {self.length_mm:.4g} mm)",
                     fontsize=9)
        a1.legend(fontsize=8)
        a2.fill_between(grid, ph - z * s_ph, ph + z * s_ph, color="C1", alpha=0.25)
        a2.plot(grid, ph, color="C1")
        a2.errorbar(f, np.degrees(np.angle(Gd)), yerr=np.degrees(z * sd / np.abs(Gd)), fmt="o", ms=4, color="k",
                    capsize=2)
        a2.set_ylabel("phase of G [deg]")
        a2.set_xlabel("frequency [Hz]")
        files = [out / "tensile_modulus.png"]
        save(fig, files[-1], dpi=120)
        fig, ax = subplots(figsize=(5.5, 3.5))
        h = np.asarray(self.loss_history)
        k = np.arange(len(h))
        ax.semilogy(k[:self.lbfgs_steps], h[:self.lbfgs_steps], label="optax L-BFGS")
        ax.semilogy(k[self.lbfgs_steps:], h[self.lbfgs_steps:], label="Levenberg-Marquardt polish")
        ax.set_xlabel("iteration")
        ax.set_ylabel("loss = chi^2 / 2")
        ax.set_title("Tensile power-sum fit: convergence", fontsize=9)
        ax.legend(fontsize=8)
        files.append(out / "tensile_loss.png")
        save(fig, files[-1], dpi=120)
        return files


def _tolist(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [_tolist(x) for x in v]
    if isinstance(v, (np.floating,)):
        return float(v)
    return v
