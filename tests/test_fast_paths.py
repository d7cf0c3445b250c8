"""The fast paths of the transients equal the reference formulas to round-off.

* drive.reduced_accelerations (block structure of J, Schur complement on the rigid
  coordinates) = jnp.linalg.solve(*drive.reduced_system(...)) (dense J^T M J);
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

from beltjax import drive, statics
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
    fast = drive.reduced_accelerations(qi, qd, sc, inst, rm, t=t)
    M, F = drive.reduced_system(qi, qd, sc, inst, t=t)
    ref = jnp.linalg.solve(M, F)
    np.testing.assert_allclose(fast, ref, rtol=1e-9, atol=1e-9 * float(jnp.max(jnp.abs(ref))))
    # and its derivative (the Newton Jacobian of the implicit solvers)
    Jf = jax.jacfwd(lambda x: drive.reduced_accelerations(x, qd, sc, inst, rm, t=t))(qi)
    Jr = jax.jacfwd(lambda x: jnp.linalg.solve(*drive.reduced_system(x, qd, sc, inst, t=t)))(qi)
    np.testing.assert_allclose(Jf, Jr, rtol=1e-8, atol=1e-8 * float(jnp.max(jnp.abs(Jr))))


def test_span_columns_are_the_constant_selection():
    sc = _scene("ancf", elements=2)
    inst = statics.install(sc)
    n, nr = drive.n_independent(sc), drive.n_rigid(sc)
    idx = drive.span_coordinate_index(sc)
    qi = drive.installed_coordinates(sc, inst).at[:nr].add(0.05)
    J = jax.jacfwd(lambda x: drive.full_coordinates(x, sc, inst, t=0.01))(qi)
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
