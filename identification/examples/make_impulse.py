"""Synthesise the impulse-response example (``impulse/``) with beltjax itself.

SIMULATED, not measured: the thesis prints no impulse-response samples (Fig. 7.68 is a plot).
The record is a beltjax transient of the thesis' tensioner bench in the rotational
(Newton–Euler) model, built from ../shared/../scenes/sim_tensioner_installation.toml, i.e. from
the thesis' published parameters (../shared/reference/thesis_reference.json ``bench``: pulleys,
tensioner spring k = 21.14 N m/rad and theta_0 = 94.5 deg, its viscous damping estimate
c_t1 = 0.1 N m s/rad, belt EA, rhoA; belt damping CA = 3.33 N s from belt B's loss factor, see
that scene), with the crank held, starting at rest in static equilibrium:

* excitation: a hammer blow on the tensioner arm, a moment of HAMMER_NM for HAMMER_S
  (``[[torque]]`` on ``tensioner_arm`` with a time window);
* response: the arm angle (deg) as an angle sensor would read it, every OUTPUT_DT_S, with white
  noise of NOISE_DEG added (seed 768); the first ``t_start_s`` of the record (hammer contact and
  the arm-against-belt mode near 495 Hz, which dies out within ~30 ms) is left out of the fit.

Expected values (printed by this script and written into dataset.toml and expected.json): the natural
frequencies and damping ratios of the same drive linearised at its equilibrium, from the
eigenvalues of the damped first-order system [[0, I], [-M^-1 K, -M^-1 C]] with K from
``drive_modal.linearise`` and C = -dF/dq' of the transient's forces (belt CA and tensioner
damping).  The transient integrator (generalized-alpha at rho_inf = 1, the implicit midpoint
rule, dt = DT_S) lowers each frequency by the factor atan(pi f dt) / (pi f dt) (2.7e-4 at 90 Hz)
and has no numerical damping.  The blow is small (the arm swings by about ±0.02 deg): a 10 times
harder blow shifts the arm mode's damping ratio by 0.4 % (the drive's geometry is nonlinear).

Run from the repository root (about a minute: compiling the statics and the integrator):
``python identification/examples/make_impulse.py``.
"""

from __future__ import annotations

import json
import math
import pathlib

import jax
import jax.numpy as jnp
import numpy as np

import beltjax  # noqa: F401  (float64)
from beltjax import runtime

runtime.configure()  # threads and XLA pool before the first JAX computation
from beltjax import drive, drive_modal, statics, transient
from beltjax.scene import loads_scene

HERE = pathlib.Path(__file__).resolve().parent
REPO = HERE.parents[1]
SCENE = REPO / "scenes" / "sim_tensioner_installation.toml"
OUT = HERE / "impulse"

HAMMER_NM, HAMMER_S = 0.5, 1e-3  # moment on the arm (N m) and its duration (s)
DT_S, OUTPUT_DT_S, T_END_S = 1e-4, 5e-4, 0.8
T_START_S = 0.05  # fit from here on
NOISE_DEG = 5e-5
SEED = 768


def bench_scene(with_hammer: bool = True):
    """The tensioner bench (rotational model, crank held, belt and tensioner damping) at rest,
    with the hammer blow on the arm and the simulation settings of this example."""
    text = SCENE.read_text()
    text = text.split("\n[initial]\n")[0]  # start from the static equilibrium, not the installation
    text = text.replace('description = "', 'description = "Impulse example: ', 1)
    if with_hammer:
        text += (f"\n[[torque]]\npulley = \"tensioner_arm\"\nmean_Nm = {HAMMER_NM}\n"
                 f"t_start_s = 0.0\nt_end_s = {HAMMER_S}\n")
    text += f"\n[simulation]\ndt_s = {DT_S}\nrho_inf = 1.0\noutput_dt_s = {OUTPUT_DT_S}\n"
    return loads_scene(text, source="make_impulse.py")


def linear_modes(scene) -> tuple[np.ndarray, np.ndarray]:
    """(natural frequencies Hz, damping ratios) of the drive linearised at its static equilibrium."""
    sc = drive.canonical(scene)
    st = statics.analyse_statics(sc, 0.0)
    qi = jnp.asarray(st.qi)
    M, _, K = drive_modal.linearise(qi, sc, st.inst)
    Mf = drive.full_mass_matrix(sc, st.inst)
    force = lambda v: drive.reduced_system(qi, v, sc, st.inst, M_full=Mf, t=0.0)[1]  # noqa: E731
    C = -jax.jacfwd(force)(jnp.zeros_like(qi))
    M, K, C = (np.asarray(a) for a in (M, K, C))
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)


def midpoint(f_hz: float, dt: float = DT_S) -> float:
    """Frequency (Hz) at which the implicit midpoint rule (step dt s) turns a mode of f_hz."""
    return math.atan(math.pi * f_hz * dt) / (math.pi * dt)


def main() -> None:
    scene = bench_scene()
    fn, zeta = linear_modes(bench_scene(with_hammer=False))
    for f, z in zip(fn, zeta):
        print(f"linearised: f_n = {f:.4f} Hz ({midpoint(f):.4f} Hz with the integrator), zeta = {z:.5f}")
    res = transient.simulate(scene, T_END_S)
    t = res.t
    angle = res.channels["arm_angle_deg"]
    rng = np.random.default_rng(SEED)
    y = angle + rng.normal(0.0, NOISE_DEG, t.size)
    print(f"arm angle {angle[0]:.4f} deg at rest, swing {np.ptp(angle[t >= T_START_S]):.4f} deg after {T_START_S} s")
    OUT.mkdir(exist_ok=True)
    shown = [(f, z) for f, z in zip(fn, zeta) if f < 1 / (2 * OUTPUT_DT_S)]
    expect = ", ".join(f"{midpoint(f):.3f} Hz / zeta {z:.5f}" for f, z in shown)
    lines = [
        "# synthesised by identification/examples/make_impulse.py from a beltjax transient (rotational model) of "
        "scenes/sim_tensioner_installation.toml (thesis bench parameters, ../shared/reference/thesis_reference.json): "
        f"{HAMMER_NM} N m on the tensioner arm for {HAMMER_S * 1e3:g} ms; arm angle (deg) + noise {NOISE_DEG} deg; "
        f"linearised modes {expect}",
        "time_s,response",
    ]
    lines += [f"{ti:.4f},{yi:.8f}" for ti, yi in zip(t, y)]
    (OUT / "tensioner_arm.csv").write_text("\n".join(lines) + "\n")
    (OUT / "dataset.toml").write_text("\n".join([
        "# Impulse response of the tensioner bench: SIMULATED by make_impulse.py (beltjax transient of the",
        "# rotational model with the thesis' bench parameters; a hammer blow on the tensioner arm; the arm",
        "# angle with noise).  beltjax fit identification/examples/impulse/dataset.toml",
        "# Expected (the drive linearised at rest; the highest mode is gone after t_start_s):",
        *[f"#   f_n = {f:.3f} Hz ({midpoint(f):.3f} Hz with the integrator's period error), zeta = {z:.5f}"
          for f, z in zip(fn, zeta)],
        "[[impulse.record]]",
        'name = "tensioner arm"',
        'file = "tensioner_arm.csv"   # time_s (s), response = arm angle (deg)',
        "modes = 2",
        f"t_start_s = {T_START_S}      # after the blow and the ~495 Hz arm-against-belt mode",
        "",
    ]))
    expected = dict(
        source="beltjax transient by make_impulse.py; values of the drive linearised at rest",
        frequencies_hz=[float(f) for f in fn],
        frequencies_with_integrator_hz=[midpoint(float(f)) for f in fn],
        damping_ratios=[float(z) for z in zeta],
        fitted_modes=[0, 1],
    )
    (OUT / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")
    print(f"wrote {OUT / 'tensioner_arm.csv'} ({t.size} rows), dataset.toml and expected.json")


if __name__ == "__main__":
    main()
