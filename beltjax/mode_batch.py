"""Batched matching of many cases' modes to one reference (a sweep's nominal), in numpy: the
result of :class:`beltjax.mode_tracking.Tracker` (a fresh tracker seeded with the reference,
one step per case) for every case whose match is certain, without a Python loop over cases.

Measured need: a GPU computes the statics and modes of 2,048 cases of the two-pulley bench in
93 ms, and the tracker's loop took 3 s for them on the host (benchmarks/README.md §6b).

A case is matched here when its shapes are real and M-orthonormal (the non-gyroscopic
eigen-solve: one column per mode) and every reference curve's best projection onto a cluster of
the case's repeated modes is either above :data:`SURE` or below :data:`ABSENT`, with no cluster
chosen by more curves than it has modes.  Then the tracker's optimal assignment is exactly
"each sure curve to its best cluster" (a curve's projections onto the clusters sum to at most 1,
and so do a cluster's over the orthonormal curves per mode: moving a sure curve loses more than
any other curve can gain), absent curves stay unmatched (below the tracker's MIN_MAC), a cluster's
curves take its modes in ascending order, and each curve's MAC after the tracker's Procrustes
rotation of the cluster is |sqrt(M^H M)_kk|^2 with M = W_c^H P (the cluster's shapes against
its curves').  Every other case is left to the tracker (``done`` False).
"""

from __future__ import annotations

import numpy as np

from beltjax.mode_tracking import RTOL_REPEATED

#: a curve whose best cluster projection exceeds this is matched to it
SURE = 0.8
#: a curve whose best cluster projection is below this is absent from the case
ABSENT = 0.1


def projections(W, P, xp=np):
    """Projections (..., r, c) of the reference's unit whitened shapes P (n, r) onto the unit
    columns of W (..., n, c): the complex curve . mode products whose squares are the MACs.
    ``xp``: numpy, or jax.numpy inside a compiled case (a sweep computes them on the device so
    that a chunk's shapes need not travel to the host)."""
    nrm = xp.linalg.norm(W, axis=-2, keepdims=True)
    return xp.matmul(xp.conj(P).T, W / xp.where(nrm > 0, nrm, 1.0))


def match(F, A, owner, rtol: float = RTOL_REPEATED):
    """Frequencies and MACs of the reference curves in each case.

    F (B, k) Hz ascending; A (B, r, c) the reference's unit shapes projected on each case's unit
    whitened shapes (:func:`projections`); owner (B, c) mode of each column.  Returns (freqs (B,
    r) Hz, NaN where a curve is absent; mac (B, r); done (B,) bool: the cases matched here, the
    rest left for the tracker).
    """
    F, A, owner = np.asarray(F, float), np.asarray(A), np.asarray(owner)
    B, k = F.shape
    r = A.shape[1]
    out_f, out_mac = np.full((B, r), np.nan), np.full((B, r), np.nan)
    done = np.zeros(B, bool)
    if B == 0 or A.shape[2] != k or owner.shape != (B, k):  # one column per mode (the real eigen-solve)
        return out_f, out_mac, done
    ok = np.all(np.isfinite(F), axis=1) & np.all(np.isfinite(A), axis=(1, 2)) & np.all(owner == np.arange(k), axis=1)
    if not ok.any():
        return out_f, out_mac, done
    Fo, A = F[ok], A[ok]
    same = np.abs(np.diff(Fo, axis=1)) <= rtol * np.maximum(np.abs(Fo[:, 1:]), np.abs(Fo[:, :-1]))
    ids = np.concatenate([np.zeros((len(Fo), 1), int), np.cumsum(~same, axis=1)], axis=1)  # (b, k) cluster ids
    C = ids[:, :, None] == ids[:, None, :]  # (b, k, k) same cluster
    single = np.abs(A) ** 2
    sub = single @ C  # projection of each curve onto each mode's cluster
    best = np.argmax(sub, axis=2)  # the first member of the best cluster
    bv = np.take_along_axis(sub, best[:, :, None], axis=2)[:, :, 0]
    sure, absent = bv > SURE, bv < ABSENT
    cid = np.take_along_axis(ids, best, axis=1)  # (b, r) cluster of each curve's best
    onehot = sure[:, :, None] & (cid[:, :, None] == np.arange(k)[None, None, :])  # (b, r, k): curve -> cluster id
    count = onehot.sum(axis=1)  # (b, k) sure curves per cluster id
    size = (ids[:, :, None] == np.arange(k)[None, None, :]).sum(axis=1)  # (b, k) modes per cluster id
    good = np.all(sure | absent, axis=1) & np.all(count <= size, axis=1)
    rank = np.take_along_axis(np.cumsum(onehot, axis=1), cid[:, :, None], axis=2)[:, :, 0] - 1  # among its cluster's
    index = best + rank  # clusters are contiguous and ascending: the rank-th member
    f = np.where(sure, np.take_along_axis(Fo, np.clip(index, 0, k - 1), axis=1), np.nan)
    mac = np.where(sure, bv, np.nan)
    # clusters with several sure curves: the MAC after the Procrustes rotation, |sqrt(M^H M)_kk|^2
    multi = sure & (np.take_along_axis(count, cid, axis=1) > 1) & good[:, None]
    if multi.any():
        mb_, mr_ = np.nonzero(multi)
        mc_ = cid[mb_, mr_]
        o = np.lexsort((mr_, mc_, mb_))  # by case, cluster, then curve
        mb_, mr_, mc_ = mb_[o], mr_[o], mc_[o]
        start = np.flatnonzero(np.r_[True, (np.diff(mb_) != 0) | (np.diff(mc_) != 0)])
        a_g = np.diff(np.r_[start, len(mb_)])  # curves per (case, cluster) group
        b_g = mb_[start]
        p_g = size[b_g, mc_[start]]  # modes of the group's cluster
        first = best[b_g, mr_[start]]  # its first mode
        for a, p in set(zip(a_g.tolist(), p_g.tolist())):
            sel = np.flatnonzero((a_g == a) & (p_g == p))
            bs = b_g[sel]
            cv = mr_[start[sel][:, None] + np.arange(a)]  # (m, a) curves, ascending
            mb = first[sel][:, None] + np.arange(p)  # (m, p) the cluster's modes
            G = A[bs[:, None, None], cv[:, :, None], mb[:, None, :]]  # (m, a, p) = P_curves^H W_c
            H = G @ np.conj(np.swapaxes(G, 1, 2))  # (m, a, a) = M^H M
            lam, V = np.linalg.eigh(H)
            S = (V * np.sqrt(np.clip(lam, 0.0, None))[:, None, :]) @ np.conj(np.swapaxes(V, 1, 2))
            mac[bs[:, None], cv] = np.abs(np.diagonal(S, axis1=1, axis2=2)) ** 2
    idx = np.flatnonzero(ok)[good]
    out_f[idx], out_mac[idx], done[idx] = f[good], mac[good], True
    return out_f, out_mac, done
