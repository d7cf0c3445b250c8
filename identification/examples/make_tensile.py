"""SYNTHESISES example tensile-test datasets (not measurements) from the thesis' Table 6.1.

The thesis prints only the fitted power-sum parameters of its tensile tests (Table 6.1, belts
"A", "B", "C"), not the records.  This script makes records that such a test would give if the
belt followed the published model exactly: for each belt, 12 sinusoidal tests from 0.01 Hz to
150 Hz at a mean force of 400 N and a force amplitude of 180 N (the thesis' 160-200 N), the
displacement amplitude and phase from G(f) = a1 f^b1 + a2 f^b2 (N/mm, f in Hz, specimen
length L of Table 6.1), 100 samples per cycle, 2 cycles at 0.01 Hz, 3 at 0.05 Hz and 4 above,
and seeded Gaussian noise of 0.5 % of each channel's amplitude on both channels.  Relaxation
and drift are left out.  Phases follow ``identification.tensile``: signals are
``mean + Re(Y e^{-i w t})`` and F = G X, so the specimen dissipates (Im G < 0, as in Table 6.1).

Run from the repository root (needs ``../shared/reference/thesis_reference.json``, read at
generation time; the generated folders are committed, so using them does not)::

    python identification/examples/make_tensile.py

Writes ``identification/examples/tensile_belt_{A,B,C}/`` with ``dataset.toml`` and one CSV per
record (columns time_s, displacement_m, force_N; first line a '#' comment saying it is
synthesised).
"""

from __future__ import annotations

import json
import math
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
REFERENCE = HERE.parents[2] / "shared" / "reference" / "thesis_reference.json"
FREQUENCIES_HZ = (0.01, 0.05, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 60.0, 100.0, 150.0)
MEAN_FORCE_N = 400.0
FORCE_AMPLITUDE_N = 180.0
SAMPLES_PER_CYCLE = 100
NOISE_SHARE = 0.005
SEEDS = {"A": 61, "B": 62, "C": 63}


def cycles(f: float) -> int:
    """Cycles recorded at frequency f (Hz): fewer for the slowest tests."""
    return 2 if f < 0.03 else 3 if f < 0.09 else 4


def modulus(params: dict, f: float) -> complex:
    """G(f) = a1 f^b1 + a2 f^b2 in N/mm (f in Hz) from Table 6.1 parameters ([re, im] pairs)."""
    c = {k: complex(*params[k]) for k in ("a1", "a2", "b1", "b2")}
    return c["a1"] * f ** c["b1"] + c["a2"] * f ** c["b2"]


def record(params: dict, f: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One synthetic test at f (Hz): time (s), displacement (m), force (N)."""
    G = 1000.0 * modulus(params, f)                    # N/m
    F_hat = FORCE_AMPLITUDE_N + 0j
    X_hat = F_hat / G
    x_mean = MEAN_FORCE_N / (1000.0 * modulus(params, 0.01).real)
    n = cycles(f) * SAMPLES_PER_CYCLE + 1
    t = np.arange(n) / (f * SAMPLES_PER_CYCLE)
    phase = rng.uniform(0.0, 2.0 * math.pi)
    e = np.exp(-1j * (2.0 * math.pi * f * t + phase))
    x = x_mean + (X_hat * e).real + NOISE_SHARE * abs(X_hat) * rng.standard_normal(n)
    F = MEAN_FORCE_N + (F_hat * e).real + NOISE_SHARE * abs(F_hat) * rng.standard_normal(n)
    return t, x, F


def write_belt(belt: str, params: dict, out: pathlib.Path) -> list[pathlib.Path]:
    """dataset.toml and the CSVs of one belt in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(SEEDS[belt])
    L = params["L_m"]
    toml = [
        f"# SYNTHESISED by make_tensile.py from the thesis' Table 6.1 (belt {belt}), not measured:",
        f"# F = {MEAN_FORCE_N:g} + {FORCE_AMPLITUDE_N:g} cos(w t + phase) N, displacement from G(f), "
        f"{100 * NOISE_SHARE:g} % noise on both channels",
        "[tensile]",
        f"specimen_length_m = {L}",
        "scene_frequency_hz = 10.0",
    ]
    files = []
    for f in FREQUENCIES_HZ:
        t, x, F = record(params, f, rng)
        name = f"tensile_f{f:g}.csv"
        lines = [f"# synthesised by make_tensile.py from Table 6.1 belt {belt} (f = {f:g} Hz)",
                 "time_s,displacement_m,force_N"]
        lines += [f"{a:.9g},{b:.8e},{c:.6f}" for a, b, c in zip(t, x, F)]
        (out / name).write_text("\n".join(lines) + "\n")
        files.append(out / name)
        toml += ["", "[[tensile.record]]", f'file = "{name}"', f"frequency_hz = {f:g}"]
    (out / "dataset.toml").write_text("\n".join(toml) + "\n")
    return files + [out / "dataset.toml"]


def main() -> int:
    if not REFERENCE.is_file():
        print(f"make_tensile.py: {REFERENCE} not found (the thesis reference numbers)", file=sys.stderr)
        return 1
    belts = json.loads(REFERENCE.read_text())["tensile_test_complex_modulus"]["belts"]
    total = 0
    for belt in ("A", "B", "C"):
        files = write_belt(belt, belts[belt], HERE / f"tensile_belt_{belt}")
        size = sum(p.stat().st_size for p in files)
        total += size
        print(f"belt {belt}: {len(files) - 1} records in {files[0].parent.relative_to(HERE.parent.parent)} "
              f"({size / 1024:.0f} KiB)")
    print(f"total {total / 1024:.0f} KiB (synthesised from Table 6.1, not measured)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
