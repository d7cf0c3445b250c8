"""The batched matching of a sweep's modes (beltjax.mode_batch) gives the tracker's result."""

from __future__ import annotations

import dataclasses
import pathlib

import equinox as eqx
import numpy as np

from beltjax import mode_batch, mode_tracking, sweep, sweep_modes
from beltjax.scene import load_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_batched_matching_equals_the_tracker(monkeypatch):
    """On a sweep of the two-pulley bench (its transverse modes come in repeated pairs, one per
    span, so the clusters and their Procrustes rotation are exercised) the batched matching
    takes every case and gives the tracker's frequency columns and MACs (a fresh tracker seeded
    with the nominal's modes, one step per case)."""
    scene = load_scene(ROOT / "scenes" / "two_pulley_T200.toml")
    scene = eqx.tree_at(lambda s: s.model, scene, dataclasses.replace(scene.model, elements_per_span=4))
    T, EI = np.meshgrid(np.linspace(150.0, 650.0, 6), np.linspace(0.02, 0.05, 4), indexing="ij")
    values = {"belt.static_tension": T.ravel(), "belt.EI": EI.ravel()}
    chunks = []
    real = sweep_modes.track_chunk

    def keep(out, refs, modes):  # the raw chunk, before tracking
        chunks.append(({k: np.array(v) for k, v in out.items()}, refs))
        return real(out, refs=refs, modes=modes)

    monkeypatch.setattr(sweep_modes, "track_chunk", keep)
    sweep.evaluate(scene, values, ("statics", "modal"), 8, chunk=8)
    for out, refs in chunks:
        ref = refs["modal"][0]
        F, W, own = out["frequencies_hz"], out["modal_W"], out["modal_owner"]
        A = out["modal_proj"]  # computed on the device, in the compiled case
        np.testing.assert_allclose(A, mode_batch.projections(W, ref.W), rtol=0, atol=1e-12)
        f, mac, done = mode_batch.match(F, A, own)
        assert done.all()
        for i in range(len(F)):
            md = mode_tracking.mode_basis(F[i], W[i], own[i])
            index, m = mode_tracking.Tracker(ref).step(md)
            n = ref.freqs.size
            found = index[:n] >= 0
            want = np.full(n, np.nan)
            want[found] = md.freqs[index[:n][found]]
            assert np.array_equal(np.isnan(f[i]), np.isnan(want))
            assert np.allclose(f[i][found], want[found], rtol=1e-12)
            assert np.allclose(mac[i][found], m[:n][found], rtol=1e-9, atol=1e-12)


def test_batched_matching_with_triples_swaps_and_absent_curves():
    """Synthetic cases (random orthonormal shapes): clusters of three and two repeated modes, modes
    swapped against the reference's order, a reference curve absent from every case, and cases
    the batched matching must leave to the tracker (a curve between two modes); where it takes a
    case its result is the tracker's."""
    rng = np.random.default_rng(3)
    n, k, B = 14, 8, 40
    freqs = np.array([1.0, 2.0, 3.0, 3.0, 3.0, 5.0, 6.0, 6.0])
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    ref = mode_tracking.mode_basis(freqs, Q[:, :k])
    ref = mode_tracking.Modes(np.r_[ref.freqs, 7.0], np.c_[ref.W, Q[:, k]].astype(complex), np.r_[ref.cluster, 9])
    F, W = np.zeros((B, k)), np.zeros((B, n, k))
    for b in range(B):
        R = np.eye(k)
        for c in (slice(2, 5), slice(6, 8)):  # any basis of the repeated modes' eigenspace
            R[c, c], _ = np.linalg.qr(rng.standard_normal((R[c, c].shape[0],) * 2))
        Wb = Q[:, :k] @ R
        f = freqs * (1.0 + 0.01 * rng.standard_normal())
        if b % 3 == 1:  # the two lowest modes crossed: the case's 1st mode has the reference's 2nd shape
            Wb[:, :2] = Wb[:, [1, 0]]
        if b % 5 == 2:  # the 6th mode half the reference's 6th shape, half the absent curve's
            Wb[:, 5] = (Q[:, 5] + Q[:, k]) / np.sqrt(2)
        F[b], W[b] = f, Wb
    own = np.tile(np.arange(k), (B, 1))
    A = mode_batch.projections(W, ref.W)
    f, mac, done = mode_batch.match(F, A, own)
    assert done.sum() >= B // 2 and not done[2::5].any()  # the mixed cases left to the tracker
    for i in np.flatnonzero(done):
        md = mode_tracking.mode_basis(F[i], W[i], own[i])
        index, m = mode_tracking.Tracker(ref).step(md)
        found = index >= 0
        assert not found[-1] and np.isnan(f[i, -1])  # the curve no case has
        assert f[i, 0] == F[i, 1 if i % 3 == 1 else 0]  # the crossed modes keep their columns
        want = np.full(ref.freqs.size, np.nan)
        want[found] = md.freqs[index[found]]
        assert np.array_equal(np.isnan(f[i]), np.isnan(want))
        assert np.allclose(f[i][found], want[found], rtol=1e-12)
        assert np.allclose(mac[i][found], m[found], rtol=1e-9, atol=1e-12)


def test_batched_matching_of_gyroscopic_shapes():
    """Gyroscopic modes (two columns each, one complex direction; shapes not orthogonal, as with
    a moving belt) against a gyroscopic reference: the batched matching takes the cases whose
    curves each have a clear best mode and gives the tracker's result; cases where a curve's two
    best modes are close (gyroscopic shapes, not M-orthogonal, can be) go to the tracker."""
    rng = np.random.default_rng(5)
    n, k, B = 12, 6, 30
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n)))
    U = Q[:, :k].copy()
    U[:, 0] = np.real(U[:, 0]) / np.linalg.norm(np.real(U[:, 0]))  # a rigid-body mode: one real column
    freqs = np.r_[0.0, 10.0, 20.0, 30.0, 40.0, 50.0]
    ref = mode_tracking.Modes(freqs, U.copy(), mode_tracking.clusters(freqs))
    own = np.r_[0, np.repeat(np.arange(1, k), 2)]
    F, W = np.zeros((B, k)), np.zeros((B, n, own.size), complex)
    for b in range(B):
        V = U + 0.05 * (rng.standard_normal((n, k)) + 1j * rng.standard_normal((n, k)))
        if b % 4 == 3:  # the 4th mode's shape near the 3rd's (MAC 0.92): the 3rd curve's two best close
            V[:, 3] = U[:, 2] + 0.3 * Q[:, k + 1]
        F[b] = freqs * (1 + 0.01 * b)
        phase = np.exp(1j * rng.uniform(0, 2 * np.pi, (2, k)))
        W[b] = np.c_[V[:, :1], *[np.c_[V[:, j] * phase[0, j] * 2.0, V[:, j] * phase[1, j]] for j in range(1, k)]]
    A = mode_batch.projections(W, ref.W)
    f, mac, done = mode_batch.match(F, A, np.tile(own, (B, 1)))
    assert done.sum() >= B // 2 and not done[3::4].any()
    for i in np.flatnonzero(done):
        md = mode_tracking.mode_basis(F[i], W[i], own)
        index, m = mode_tracking.Tracker(ref).step(md)
        found = index >= 0
        assert found.all()
        np.testing.assert_allclose(f[i], md.freqs[index], rtol=1e-12)
        np.testing.assert_allclose(mac[i], m, rtol=1e-9, atol=1e-12)
