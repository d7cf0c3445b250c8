"""The batched matching of a sweep's modes (beltjax.mode_batch) gives the tracker's result."""

from __future__ import annotations

import pathlib

import numpy as np

from beltjax import mode_batch, sweep
from beltjax.scene import load_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_batched_matching_equals_the_tracker(monkeypatch):
    """A sweep of the two-pulley bench (its transverse modes come in repeated pairs, one per
    span, so the clusters and their Procrustes rotation are exercised) gives the same frequency
    columns and MACs with the batched matching as with the tracker case by case, and the batch
    takes most cases."""
    scene = load_scene(ROOT / "scenes" / "two_pulley_T200.toml")
    T, EI = np.meshgrid(np.linspace(150.0, 650.0, 6), np.linspace(0.02, 0.05, 4), indexing="ij")
    values = {"belt.static_tension": T.ravel(), "belt.EI": EI.ravel()}
    taken = []
    real = mode_batch.match

    def counting(*a, **k):
        out = real(*a, **k)
        taken.append(out[2])
        return out

    monkeypatch.setattr(mode_batch, "match", counting)
    fast = sweep.evaluate(scene, values, ("statics", "modal"), modes=12, chunk=24)
    monkeypatch.setattr(mode_batch, "match", lambda F, W, own, P: (np.full((len(F), P.shape[1]), np.nan),
                                                                   np.full((len(F), P.shape[1]), np.nan),
                                                                   np.zeros(len(F), bool)))
    slow = sweep.evaluate(scene, values, ("statics", "modal"), modes=12, chunk=24)
    done = np.concatenate(taken)
    assert done.mean() > 0.9
    for key in ("frequencies_hz", "mode_mac"):
        a, b = np.asarray(fast[key]), np.asarray(slow[key])
        assert np.array_equal(np.isnan(a), np.isnan(b)), key
        assert np.allclose(a[~np.isnan(a)], b[~np.isnan(b)], rtol=1e-9, atol=1e-12), key
