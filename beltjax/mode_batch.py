"""Batched matching of many cases' modes to one reference (a sweep's nominal), in numpy: the
result of :class:`beltjax.mode_tracking.Tracker` (a fresh tracker seeded with the reference,
one step per case) for every case whose match is certain, without a Python loop over cases.

Measured need: a GPU computes the statics and modes of 2,048 cases of the two-pulley bench in
78 ms, and the tracker's loop took 3 s for them on the host (benchmarks/README.md §6b).  The
input is the projections of the reference's shapes on each case's (:func:`projections`), which
a sweep computes on the device: a chunk's shapes need not travel to the host.

A case is matched here when every reference curve's best projection onto a cluster of the
case's repeated modes is either above :data:`SURE` (and above its best projection onto any other
cluster by more than :data:`ABSENT`) or below :data:`ABSENT`, with no cluster chosen by more
curves than it has modes, and each cluster of several modes has real M-orthonormal shapes (the
non-gyroscopic eigen-solve, one column per mode; a gyroscopic mode's columns are one complex
direction, which a simple mode's first column stands for, but several of them are no basis of a
cluster: a precondition the sweep's eigen-solvers guarantee, which the projections cannot show).
Then the tracker's optimal assignment is exactly "each sure curve to its best
cluster": every sure curve has its row's maximum, and moving m of them loses more than m x
ABSENT while the m columns they free can give the absent curves at most m x ABSENT (one
augmenting path each); absent curves stay unmatched (below the tracker's MIN_MAC), a cluster's
curves take its modes in ascending order, and each curve's MAC after the tracker's Procrustes
rotation of the cluster is |sqrt(M^H M)_kk|^2 with M = W_c^H P (the cluster's shapes against
its curves').  Gyroscopic shapes are not M-orthogonal, hence the margin; orthonormal ones have
it (0.8 against at most 0.2).  Every other case is left to the tracker (``done`` False).
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
    whitened shapes (:func:`projections`); owner (B, c) mode of each column (ascending, the same in
    every case; two per gyroscopic mode, whose first stands for it as in
    :func:`beltjax.mode_tracking.mode_basis`).  Returns (freqs (B,
    r) Hz, NaN where a curve is absent; mac (B, r); done (B,) bool: the cases matched here, the
    rest left for the tracker).
    """
    F, A, owner = np.asarray(F, float), np.asarray(A), np.asarray(owner)
    B, k = F.shape
    r = A.shape[1]
    out_f, out_mac = np.full((B, r), np.nan), np.full((B, r), np.nan)
    done = np.zeros(B, bool)
    o = owner[0] if B else np.zeros(0, int)
    if B == 0 or owner.shape != (B, A.shape[2]) or np.any(owner != o) or not np.array_equal(np.unique(o), np.arange(k)):
        return out_f, out_mac, done  # not one column layout with every mode in it
    cols = np.searchsorted(o, np.arange(k)) if np.all(np.diff(o) >= 0) else None
    if cols is None:
        return out_f, out_mac, done
    ok = np.all(np.isfinite(F), axis=1) & np.all(np.isfinite(A), axis=(1, 2))  # every column finite
    A = A[:, :, cols]  # a mode's first column (a gyroscopic mode's columns are one complex direction)
    multi_col = np.bincount(o, minlength=k) > 1  # gyroscopic modes: their columns are no basis of a cluster
    if multi_col.any():  # so a case whose repeated modes have several columns goes to the tracker
        rep = np.abs(np.diff(F, axis=1)) <= rtol * np.maximum(np.abs(F[:, 1:]), np.abs(F[:, :-1]))
        ok &= ~np.any(rep & (multi_col[1:] | multi_col[:-1]), axis=1)
    if not ok.any():
        return out_f, out_mac, done
    Fo, A = (F, A) if ok.all() else (F[ok], A[ok])
    b, j = len(Fo), np.arange(k)
    new = np.concatenate([np.ones((b, 1), bool), np.abs(np.diff(Fo, axis=1))
                          > rtol * np.maximum(np.abs(Fo[:, 1:]), np.abs(Fo[:, :-1]))], axis=1)  # a cluster starts
    lo = np.maximum.accumulate(np.where(new, j, 0), axis=1)  # (b, k) first mode of each mode's cluster
    last = np.concatenate([new[:, 1:], np.ones((b, 1), bool)], axis=1)  # a cluster ends
    hi = np.minimum.accumulate(np.where(last, j, k)[:, ::-1], axis=1)[:, ::-1]  # (b, k) its last mode
    single = np.real(A * np.conj(A)) if np.iscomplexobj(A) else A * A
    sub = single.copy()  # (b, r, k) projection of each curve onto each mode's cluster
    for d in range(1, int(np.max(hi - lo)) + 1):  # clusters are contiguous: add the members d modes apart
        m = (hi[:, :-d] >= j[:-d] + d)[:, None, :]  # mode j + d in j's cluster
        sub[:, :, :-d] += np.where(m, single[:, :, d:], 0.0)
        sub[:, :, d:] += np.where(m, single[:, :, :-d], 0.0)
    best = np.argmax(sub, axis=2)  # (b, r) a member of each curve's best cluster (the members' sums
    bv = np.take_along_axis(sub, best[:, :, None], axis=2)[:, :, 0]  # differ in rounding), its projection,
    best = np.take_along_axis(lo, best, axis=1)  # and the cluster's first member (its id)
    sure, absent = bv > SURE, bv < ABSENT
    size = np.take_along_axis(hi, best, axis=1) - best + 1  # (b, r) modes of that cluster
    E = sure[:, :, None] & sure[:, None, :] & (best[:, :, None] == best[:, None, :])  # (b, r, r) sure, same cluster
    count = E.sum(axis=2)  # sure curves in each curve's cluster
    rank = np.sum(E & (np.arange(r)[None, :] < np.arange(r)[:, None]), axis=2)  # among its cluster's, ascending
    # the runner-up outside the best cluster: a sure curve must beat it by more than any absent curve
    # could gain from the column it would free (orthonormal shapes do: 0.8 against at most 0.2)
    second = np.max(np.where(lo[:, None, :] == best[:, :, None], -np.inf, sub), axis=2, initial=-np.inf)
    good = (np.all(sure | absent, axis=1) & np.all(~sure | (count <= size), axis=1)
            & np.all(~sure | (bv - second > ABSENT), axis=1))
    index = best + rank  # clusters are contiguous and ascending: the rank-th member
    f = np.where(sure, np.take_along_axis(Fo, np.clip(index, 0, k - 1), axis=1), np.nan)
    mac = np.where(sure, bv, np.nan)
    # clusters with several sure curves: the MAC after the Procrustes rotation, |sqrt(M^H M)_kk|^2
    multi = sure & (count > 1) & good[:, None]
    if multi.any():
        mb_, mr_ = np.nonzero(multi)
        mc_ = best[mb_, mr_]
        o = np.lexsort((mr_, mc_, mb_))  # by case, cluster, then curve
        mb_, mr_, mc_ = mb_[o], mr_[o], mc_[o]
        start = np.flatnonzero(np.r_[True, (np.diff(mb_) != 0) | (np.diff(mc_) != 0)])
        a_g = np.diff(np.r_[start, len(mb_)])  # curves per (case, cluster) group
        b_g = mb_[start]
        p_g = size[b_g, mr_[start]]  # modes of the group's cluster
        first = mc_[start]  # its first mode
        for a, p in set(zip(a_g.tolist(), p_g.tolist())):
            sel = np.flatnonzero((a_g == a) & (p_g == p))
            bs = b_g[sel]
            cv = mr_[start[sel][:, None] + np.arange(a)]  # (m, a) curves, ascending
            mb = first[sel][:, None] + np.arange(p)  # (m, p) the cluster's modes
            G = A[bs[:, None, None], cv[:, :, None], mb[:, None, :]]  # (m, a, p) = P_curves^H W_c
            H = G @ np.conj(np.swapaxes(G, 1, 2))  # (m, a, a) = M^H M
            mac[bs[:, None], cv] = np.abs(_sqrt_diagonal(H)) ** 2
    idx = np.flatnonzero(ok)[good]
    out_f[idx], out_mac[idx], done[idx] = f[good], mac[good], True
    return out_f, out_mac, done


def _sqrt_diagonal(H, closed: bool = True):
    """Diagonals (m, a) of the square roots of Hermitian positive semi-definite H (m, a, a): in
    closed form for pairs, sqrt(H) = (H + sqrt(det H) I) / sqrt(tr H + 2 sqrt(det H)) (the pairs
    of equal spans: numpy's batched eigh of 2x2 matrices took 15 ms per 2,048 cases), else, and
    where a pair is nearly singular (sqrt(det H) would lose digits), by eigh."""
    if closed and H.shape[1] == 2:
        tr = np.real(H[:, 0, 0] + H[:, 1, 1])
        d = np.sqrt(np.clip(np.real(H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] * H[:, 1, 0]), 0.0, None))
        t = np.sqrt(np.clip(tr + 2.0 * d, 0.0, None))
        out = (np.real(np.stack([H[:, 0, 0], H[:, 1, 1]], axis=1)) + d[:, None]) / np.where(t > 0, t, 1.0)[:, None]
        near = d < 1e-4 * tr
        if near.any():
            out[near] = _sqrt_diagonal(H[near], closed=False)
        return out
    lam, V = np.linalg.eigh(H)
    return np.real(np.einsum("mij,mj,mij->mi", V, np.sqrt(np.clip(lam, 0.0, None)), np.conj(V)))
