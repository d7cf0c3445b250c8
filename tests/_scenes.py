"""Shared test helpers: the example scene files as text, edits of that text, and a drive's
mechanical energy."""

import pathlib
import re

SCENES = pathlib.Path(__file__).resolve().parents[1] / "scenes"


def scene_text(name):
    """The text of the example scene file ``scenes/<name>``."""
    return (SCENES / name).read_text()


def loaded_two_pulley(fidelity: str, torque: float = 6.0, extra_belt: str = "") -> str:
    """The two-pulley bench (``two_pulley_T400.toml``) driven at 800 rpm with ``torque`` (N m) on
    the alternator, in ``fidelity`` (4 elements per span), ``extra_belt`` added to its [belt]."""
    txt = scene_text("two_pulley_T400.toml")
    txt = txt.replace("driven = false", "driven = true").replace("speed_rpm = 0.0", "speed_rpm = 800.0", 1)
    txt = re.sub(r'fidelity = "ancf"', f'fidelity = "{fidelity}"', txt)
    txt = re.sub(r"elements_per_span = \d+", "elements_per_span = 4", txt)
    txt = txt.replace("static_tension = 400.0", "static_tension = 400.0\n" + extra_belt)
    return txt + f'\n[[torque]]\npulley = "alternator"\nmean_Nm = {torque}\n'


def substitute(text, *pairs):
    """Replace each (old, new) in text; every old string must occur exactly once."""
    for old, new in pairs:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text


def mechanical_energy(sc, inst, extra=None):
    """Mechanical energy (J) of states y = (q_i, q_i'), jitted and vmapped: kinetic, the spans'
    potential, the tensioner spring's, plus ``extra(qi, scene)`` (J) for what a test adds (a
    decoupler's spring, a constant load's -M psi)."""
    import jax
    import jax.numpy as jnp

    from beltjax import drive

    sc = drive.canonical(sc)
    n = drive.n_independent(sc)
    t = sc.tensioner

    def energy(y):
        qi, qd = y[:n], y[n:]
        M, _ = drive.reduced_system(qi, qd, sc, inst)
        E, _ = drive.split_full(drive.full_coordinates(qi, sc, inst), sc)
        V = sum(drive.span_potential(E[s], s, sc, inst) for s in range(E.shape[0]))
        if t is not None:
            _, theta = drive.angles_and_arm(qi, sc, inst)
            V = V + 0.5 * t.spring_stiffness * (theta - jnp.deg2rad(t.spring_preload_deg)) ** 2
        if extra is not None:
            V = V + extra(qi, sc)
        return 0.5 * qd @ M @ qd + V

    return jax.jit(jax.vmap(energy))
