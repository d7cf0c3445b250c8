"""The fast paths of the transients equal the reference formulas to round-off.

* drive.reduced_accelerations (block structure of J, Schur complement on the rigid
  coordinates; for the rotational model the bars' forces through the span lengths) =
  jnp.linalg.solve(*drive.reduced_system(...)) (dense J^T M J), with every effect and load
  the rotational model takes;
* the rotational model's compressed bodies' Jacobian (drive.bodies_jacobian) = jacfwd;
* drive.span_coordinate_index: the span columns of dPhi/dq_i are that constant selection;
* the generalized-alpha Newton solve with the kept permutation = jax.scipy.linalg.lu_solve.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import drive, span, statics
from beltjax import scene as scene_mod
from beltjax.scene import load_scene

SCENES = Path(__file__).resolve().parents[1] / "scenes"


def _scene(fidelity: str, elements: int = 1):
    sc = load_scene(SCENES / "tensioner_bench_stage2.toml")
    model = dataclasses.replace(sc.model, fidelity=fidelity, elements_per_span=elements, effects=("transport",))
    return drive.canonical(dataclasses.replace(sc, model=model))


@pytest.mark.parametrize("fidelity", ["ancf", "rotational"])
def test_reduced_accelerations_equal_dense_solve(fidelity):
    sc = _scene(fidelity)
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    rng = np.random.default_rng(0)
    qi = drive.installed_coordinates(sc, inst) + 1e-4 * jnp.asarray(rng.standard_normal(n))
    qd = jnp.asarray(rng.standard_normal(n))
    t = 0.013
    rm = drive.reduced_mass(sc, inst)

    def both(x):  # the fast path and the dense solve, stacked (one compiled program for both)
        y = jnp.stack([drive.reduced_accelerations(x, qd, sc, inst, rm, t=t),
                       jnp.linalg.solve(*drive.reduced_system(x, qd, sc, inst, t=t))])
        return y, y

    (Jf, Jr), (fast, ref) = jax.jit(jax.jacfwd(both, has_aux=True))(qi)  # values and Jacobians
    np.testing.assert_allclose(fast, ref, rtol=1e-9, atol=1e-9 * float(jnp.max(jnp.abs(ref))))
    # and its derivative (the Newton Jacobian of the implicit solvers)
    np.testing.assert_allclose(Jf, Jr, rtol=1e-8, atol=1e-8 * float(jnp.max(jnp.abs(Jr))))


def _lagrange(sc, inst, qi, qd, t):
    """M_ii and F_ii of Lagrange's equations by autodiff of the drive's kinetic energy
    T(q_i, q_i', t) (bodies, and the spans' 1/2 int rhoA |r_t + c r_x|^2 dx with c the drive
    pulley's rim speed / lam) and its strain energy and spring, written out here."""
    n = len(sc.route.order)
    idx = span.element_index(sc.model.elements_per_span)
    Le, ns, mb = drive.element_length(sc, inst), drive.n_span_coordinates(sc), drive.body_masses(sc, inst)
    t = jnp.asarray(t)

    def T(x, xd, tt):
        q, v = jax.jvp(lambda y, s: drive.full_coordinates(y, sc, inst, t=s), (x, tt), (xd, jnp.ones_like(tt)))
        E, Ed = q[:ns].reshape(n, -1), v[:ns].reshape(n, -1)
        c = drive.transient_transport_speed(sc, inst, v, tt)[0]
        return sum(span.span_kinetic_energy(E[s], Ed[s], c, sc.belt.rhoA, Le[s], idx) for s in range(n)) + 0.5 * jnp.sum(
            mb * v[ns:] ** 2)

    def V(x, tt):
        E, B = drive.split_full(drive.full_coordinates(x, sc, inst, t=tt), sc)
        U = sum(span.span_strain_energy(E[s], drive.section(sc), Le[s], idx, sc.model.bending) for s in range(n))
        if sc.tensioner is not None:
            k = sc.tensioner
            U = U + 0.5 * k.spring_stiffness * (B[-1, 2] - jnp.deg2rad(k.spring_preload_deg)) ** 2
        return U

    M = jax.hessian(T, argnums=1)(qi, qd, t)
    _, dp = jax.jvp(lambda x, xd, tt: jax.grad(T, argnums=1)(x, xd, tt), (qi, qd, t),
                    (qd, jnp.zeros_like(qd), jnp.ones_like(t)))
    return M, jax.grad(T)(qi, qd, t) - dp - jax.grad(V)(qi, t)


@pytest.mark.parametrize("base, crank_driven", [("tensioner_bench_stage2", False), ("two_pulley_T600", False),
                                                 ("two_pulley_T600", True)])
def test_hybrid_equations_are_lagrange_with_the_travel(base, crank_driven):
    """The hybrid model's reduced equations in a transient, M_ii q_i'' = F_ii (drive.reduced_system,
    and the structured drive.reduced_accelerations), are Lagrange's equations of the drive's
    energies (to 1e-12), with the crank driven at 600 rpm (the belt's travel prescribed) or free
    (the travel follows it: c = R theta_c' / lam depends on the crank's rate, which couples the
    crank to every span through the mass matrix, drive.travel_inertia)."""
    sc = load_scene(SCENES / f"{base}.toml")
    model = dataclasses.replace(sc.model, fidelity="ancf", elements_per_span=2, effects=("transport",))
    pulleys = tuple(dataclasses.replace(p, driven=crank_driven and k == 0, speed_rpm=jnp.asarray(600.0) if k == 0 else p.speed_rpm)
                    for k, p in enumerate(sc.pulleys))
    sc = drive.canonical(dataclasses.replace(sc, model=model, pulleys=pulleys))
    assert drive.travel_follows_drive(sc) is not crank_driven
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    rng = np.random.default_rng(4)
    qi = drive.installed_coordinates(sc, inst) + 1e-3 * jnp.asarray(rng.standard_normal(n))
    qd = jnp.asarray(rng.standard_normal(n))
    # compiled (eager autodiff through the span loops takes tens of seconds)
    M, F = jax.jit(lambda x, xd: drive.reduced_system(x, xd, sc, inst, t=0.013))(qi, qd)
    ML, FL = jax.jit(lambda x, xd: _lagrange(sc, inst, x, xd, 0.013))(qi, qd)
    np.testing.assert_allclose(M, ML, rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(M))))
    np.testing.assert_allclose(F, FL, rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(F))))
    rm = drive.reduced_mass(sc, inst)
    fast = jax.jit(lambda x, xd: drive.reduced_accelerations(x, xd, sc, inst, rm, t=0.013))(qi, qd)
    ref = jnp.linalg.solve(M, F)
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-10 * float(jnp.max(jnp.abs(ref))))


def test_free_drive_transient_linearises_to_the_modal_analysis():
    """The tensioner bench (hybrid, 2 elements per span, every pulley free) at 3000 rpm: the
    transient's equations, whose belt travel follows the crank, linearised at the steady state
    they start from (eigenvalues of the first-order system, by jacfwd of
    drive.reduced_accelerations), have the modal analysis' first eight frequencies (which
    linearise about the steady travel) to 2e-4, and no growing mode; the steady state is one
    (accelerations below 1e-3 of g)."""
    sc = load_scene(SCENES / "tensioner_bench_stage2.toml")
    model = dataclasses.replace(sc.model, fidelity="ancf", elements_per_span=2, effects=("transport",))
    pulleys = tuple(dataclasses.replace(p, speed_rpm=jnp.asarray(3000.0)) if k == 0 else p for k, p in enumerate(sc.pulleys))
    sc = drive.canonical(dataclasses.replace(sc, model=model, pulleys=pulleys))
    assert drive.travel_follows_drive(sc)
    from beltjax import drive_modal, transient

    inst, qi, qd = transient.initial_state(sc)
    rm = drive.reduced_mass(sc, inst)
    def f(x, xd):  # the accelerations, also as the auxiliary output: values and Jacobians from one program
        a = drive.reduced_accelerations(x, xd, sc, inst, rm, t=0.0)
        return a, a

    (dq, dqd), acc = jax.jit(jax.jacfwd(f, argnums=(0, 1), has_aux=True))(qi, qd)
    n = qi.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [np.asarray(dq), np.asarray(dqd)]])
    ev = np.linalg.eigvals(A)
    hz = np.sort(ev.imag[ev.imag > 2 * np.pi * 1e-2]) / (2 * np.pi)  # the rigid turn of the loop: 0 Hz
    modal = np.asarray(drive_modal.analyse_modes(sc).frequencies_hz)
    modal = modal[modal > 0]
    print(f"\n  transient {np.round(hz[:8], 3)}\n  modal     {np.round(modal[:8], 3)}")
    assert np.max(np.abs(acc)) < 1e-2
    np.testing.assert_allclose(hz[:8], modal[:8], rtol=2e-4)
    assert np.max(ev.real) < 1e-6 * np.max(np.abs(ev))


ALL_EFFECTS = ("transport", "gravity", "belt_damping", "bearing_damping", "tensioner_damping", "unbalance",
               "speed_fluctuation")


@pytest.mark.parametrize("base", ["tensioner_bench_stage2", "two_pulley_T600"])
@pytest.mark.parametrize("crank_driven", [False, True])
def test_rotational_accelerations_with_every_effect_equal_dense_solve(base, crank_driven):
    """The rotational model's reduced accelerations (bars through the span lengths) with all
    effects, unbalance, a [[torque]] on every body, a driven or free crank, at speed."""
    sc = load_scene(SCENES / f"{base}.toml")
    effects = tuple(e for e in ALL_EFFECTS if (e != "tensioner_damping" or sc.tensioner is not None)
                    and (e != "speed_fluctuation" or crank_driven))
    model = dataclasses.replace(sc.model, fidelity="rotational", effects=effects)
    pulleys = tuple(
        dataclasses.replace(p, bearing_damping=jnp.asarray(1e-3 * (k + 1)), cm_offset=jnp.asarray([1e-3, -5e-4 * k]),
                            driven=crank_driven if k == 0 else p.driven,
                            speed_rpm=jnp.asarray(600.0 if crank_driven else 0.0) if k == 0 else p.speed_rpm,
                            fluctuation_amplitude_deg=jnp.asarray(1.0 if k == 0 else 0.0), fluctuation_frequency_hz=jnp.asarray(20.0))
        for k, p in enumerate(sc.pulleys)
    )
    belt = dataclasses.replace(sc.belt, CA=jnp.asarray(2.5))
    tens = None if sc.tensioner is None else dataclasses.replace(sc.tensioner, damping=jnp.asarray(0.2), arm_cm_distance=jnp.asarray(0.02))
    free = [p.name for p in pulleys if not p.driven] + ([scene_mod.ARM] if tens is not None else [])
    loads = tuple(
        scene_mod.Torque(pulley=name, mean_Nm=jnp.asarray(1.5), amplitude_Nm=jnp.asarray(0.7),
                         frequency_hz=jnp.asarray(33.0), phase_deg=jnp.asarray(10.0), t_start_s=jnp.asarray(0.0),
                         t_end_s=None)
        for name in free
    )
    sc = drive.canonical(dataclasses.replace(sc, model=model, pulleys=pulleys, belt=belt, tensioner=tens, torques=loads))
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    rng = np.random.default_rng(2)
    qi = drive.installed_coordinates(sc, inst) + 1e-3 * jnp.asarray(rng.standard_normal(n))
    qd = jnp.asarray(rng.standard_normal(n))
    rm = drive.reduced_mass(sc, inst)
    for t in (None, 0.013):  # compiled: run op by op, the dense reference took most of the test's time
        fast, ref = jax.jit(lambda x, v: (drive.reduced_accelerations(x, v, sc, inst, rm, t=t, speed=3.0),
                                          jnp.linalg.solve(*drive.reduced_system(x, v, sc, inst, speed=3.0, t=t))))(qi, qd)
        np.testing.assert_allclose(fast, ref, rtol=1e-10, atol=1e-10 * float(jnp.max(jnp.abs(ref))))


def test_rotational_structured_solve_on_the_eight_pulley_drive():
    """The rotational model's compressed bodies' Jacobian (one pass for all own coordinates) and
    its diagonal-plus-Schur solve equal jacfwd and the dense solve on the eight-pulley drive with a
    decoupler (its rotor a body of its own), an isolated crank (its rim a free coordinate),
    unbalance on every pulley and all effects, at random states."""
    text = (SCENES / "fead_8pulley_decoupler.toml").read_text()
    text = text.replace('effects = ["transport"', 'effects = ["unbalance", "bearing_damping", "gravity", "transport"', 1)
    text = text.replace('name = "ac"', 'name = "ac"\nbearing_damping = 1e-3\ncm_offset = [1e-3, 0.0]', 1)  # listed
    sc = scene_mod.loads_scene(text + '\n[isolator]\npulley = "crank"\nstiffness = 400.0\ndamping = 0.3\n')
    pulleys = tuple(dataclasses.replace(p, cm_offset=jnp.asarray([1e-3, -5e-4 * k]), bearing_damping=jnp.asarray(1e-3))
                    for k, p in enumerate(sc.pulleys))
    sc = drive.canonical(dataclasses.replace(sc, pulleys=pulleys))
    assert len(sc.decouplers) == 1 and drive.drive_of(sc).own_bodies[-1] == len(sc.route.order)
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    rng = np.random.default_rng(5)
    qi = drive.installed_coordinates(sc, inst) + 1e-2 * jnp.asarray(rng.standard_normal(n))
    qd = 10.0 * jnp.asarray(rng.standard_normal(n))
    rm = drive.reduced_mass(sc, inst)
    bodies = lambda x: drive.full_coordinates(x, sc, inst, t=jnp.asarray(0.013))[drive.n_span_coordinates(sc):]  # noqa: E731
    Jb, Jref = jax.jit(lambda x: (drive.bodies_jacobian(bodies, x, sc).dense(), jax.jacfwd(bodies)(x)))(qi)
    np.testing.assert_allclose(Jb, Jref, rtol=0, atol=1e-14)
    for t in (None, 0.013):  # compiled: run op by op, the dense reference took 20-40 s
        fast, ref = jax.jit(lambda x, v: (drive.reduced_accelerations(x, v, sc, inst, rm, t=t, speed=3.0),
                                          jnp.linalg.solve(*drive.reduced_system(x, v, sc, inst, speed=3.0, t=t))))(qi, qd)
        np.testing.assert_allclose(fast, ref, rtol=1e-10, atol=1e-10 * float(jnp.max(jnp.abs(ref))))


def test_span_lengths_closed_form_equals_the_kinematic_map():
    """drive.span_lengths (L + r dpsi + slides) = |end - start| of full_coordinates' bars, also far
    from the installed state (arm swung by up to 30 deg, pulleys turned by up to 0.5 rad)."""
    sc = _scene("rotational")
    inst = statics.install(sc)
    n = drive.n_independent(sc)
    rng = np.random.default_rng(3)
    for swing in (-30.0, -5.0, 0.0, 12.0, 30.0):
        qi = jnp.asarray(rng.uniform(-0.5, 0.5, n)).at[-1].set(np.radians(swing))
        E, _ = drive.split_full(drive.full_coordinates(qi, sc, inst), sc)
        direct = jnp.linalg.norm(E[:, 4:6] - E[:, 0:2], axis=1)
        np.testing.assert_allclose(drive.span_lengths(qi, sc, inst), direct, rtol=1e-13)
        # the vector field's Jacobian (slides' + one jvp along the arm) is jacfwd's
        l, J = drive.span_lengths_and_jacobian(qi, sc, inst)
        np.testing.assert_allclose(l, direct, rtol=1e-13)
        np.testing.assert_allclose(J, jax.jacfwd(drive.span_lengths)(qi, sc, inst), rtol=1e-12, atol=1e-15)


def test_span_columns_are_the_constant_selection():
    sc = _scene("ancf", elements=2)
    inst = statics.install(sc)
    n, nr = drive.n_independent(sc), drive.n_rigid(sc)
    idx = drive.span_coordinate_index(sc)
    qi = drive.installed_coordinates(sc, inst).at[:nr].add(0.05)
    J = jax.jit(jax.jacfwd(lambda x: drive.full_coordinates(x, sc, inst, t=0.01)))(qi)  # compiled: faster than op by op
    S = np.zeros((J.shape[0], n - nr))
    S[idx, np.arange(n - nr)] = 1.0
    np.testing.assert_array_equal(np.asarray(J[:, nr:]), S)


def test_lu_solve_with_permutation_equals_scipy_lu_solve():
    A = jnp.asarray(np.random.default_rng(1).standard_normal((12, 12))) + 3 * jnp.eye(12)
    b = jnp.arange(12.0)
    lu, _, perm = jax.lax.linalg.lu(A)
    x = b[perm][:, None]
    x = jax.lax.linalg.triangular_solve(lu, x, left_side=True, lower=True, unit_diagonal=True)
    x = jax.lax.linalg.triangular_solve(lu, x, left_side=True, lower=False)[:, 0]
    np.testing.assert_array_equal(np.asarray(x), np.asarray(jax.scipy.linalg.lu_solve(jax.scipy.linalg.lu_factor(A), b)))
