"""Mode tracking: which mode at one speed (or sweep case) is which mode at the next.

Sorted by frequency, the k-th mode at one speed need not be the k-th at the next: modes
cross.  Here a mode keeps its identity by its shape.  Each step compares the modes of a
new speed with the current *curves* (the last shape of each tracked mode) by the
mass-weighted modal assurance criterion

    MAC(a, b) = |x_a^H M x_b|^2 / ((x_a^H M x_a) (x_b^H M x_b)),

computed on mass-whitened shapes W = L^T X (M = L L^T; :func:`beltjax.drive_modal.tracking_shapes`),
so that MAC = |w_a^H w_b|^2 for unit columns.  Complex (gyroscopic) shapes are compared as
they are: the MAC ignores a mode's phase.  Then:

* **Repeated modes** (equal-tension, equal-length spans: frequencies equal to ``rtol``) form a
  cluster whose shapes are any basis of one eigenspace.  :func:`mode_basis` gives each cluster
  an M-orthonormal basis; a curve is matched to a cluster by its projection onto the whole
  subspace (the sum of its MACs with the cluster's basis), and the cluster's basis is then
  rotated (orthogonal Procrustes) to the shapes of the curves matched to it, so each curve
  keeps its own shape inside the pair.  :func:`localise` picks, at the start, the basis whose
  members sit in as few spans / bodies as the subspace allows (one span each for two equal
  spans).
* **Assignment**: curves and modes are paired by an optimal assignment
  (``scipy.optimize.linear_sum_assignment``) maximising the total MAC (a cluster of p modes
  offers p slots).  A curve not seen at a step keeps its last shape and may be matched later
  (with a small penalty per step missed, so the most recent curve wins a tie).
* **Veering**: near an avoided crossing the two modes exchange shapes.  Comparing each speed
  with the previous one follows the shape: where the exchange happens within one step the
  curves cross the gap (each keeps its shape); where the steps resolve a gradual exchange,
  each curve follows its branch and its *label* (computed from its shape at every speed)
  changes: :func:`label_changes` reports that, and a step whose best MAC is below
  :data:`UNCERTAIN_MAC` is reported as one the speed step does not resolve.
* **Gaps**: steps without modes (unstable, no equilibrium) are skipped; the next valid step
  is compared with the last shapes before the gap.
* **The computed window**: only the lowest modes are computed, so modes enter and leave at
  its top.  A mode matched with MAC below :data:`MIN_MAC` (or to no curve) starts a new
  curve.  Compute a margin of modes above those reported (:func:`n_computed`), so that every
  reported curve is far from the top of the window.

The matching is numpy (cheap: a (curves x modes) matrix per step); the eigen-solves stay
batched and compiled.  Use :class:`Tracker` step by step (streaming over chunks), or
:func:`track` on stacked arrays; :func:`reported` selects the curves worth reporting,
:func:`rank_masks` turns curves into per-step masks over sorted frequencies, and
:func:`follow_labels` / :func:`label_changes` read labels along a curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

#: relative frequency difference below which modes count as repeated (one eigenspace)
RTOL_REPEATED = 1e-6
#: a curve matched with a lower MAC is not continued: the mode starts a new curve
MIN_MAC = 0.3
#: a match below this MAC is reported as uncertain (the step does not resolve the change)
UNCERTAIN_MAC = 0.8
#: penalty on the MAC per step a curve was not seen (the most recent curve wins a tie)
_AGE_PENALTY = 1e-3


def n_computed(n_report: int, n_available: int) -> int:
    """Modes to compute so that ``n_report`` can be tracked: n_report + max(6, n_report // 2),
    at most ``n_available``."""
    return min(n_available, n_report + max(6, n_report // 2))


def clusters(freqs, rtol: float = RTOL_REPEATED) -> np.ndarray:
    """(m,) cluster id of each mode (ascending ``freqs``): neighbours within ``rtol`` (relative,
    chained) share an id.  Rigid-body modes (0 Hz) are repeated with each other only."""
    f = np.asarray(freqs, float)
    ids = np.zeros(len(f), int)
    for i in range(1, len(f)):
        same = abs(f[i] - f[i - 1]) <= rtol * max(abs(f[i]), abs(f[i - 1]))
        ids[i] = ids[i - 1] + (0 if same else 1)
    return ids


@dataclass
class Modes:
    """The modes of one speed (or case), ready to track.

    freqs (m,) Hz ascending; W (n, m) mass-whitened unit shapes, M-orthonormal inside each
    cluster of repeated modes; cluster (m,) ids (:func:`clusters`); V (n_full, m) full-coordinate
    shapes rotated with W (for labels), or None.
    """

    freqs: np.ndarray
    W: np.ndarray
    cluster: np.ndarray
    V: np.ndarray | None = None

    def rotate(self, members: np.ndarray, R: np.ndarray) -> None:
        """Replace the basis of the modes ``members`` (one cluster) by (basis) @ R, R unitary."""
        self.W[:, members] = self.W[:, members] @ R
        if self.V is not None:
            self.V[:, members] = self.V[:, members] @ R


def mode_basis(freqs, W, owner=None, V=None, rtol: float = RTOL_REPEATED) -> Modes:
    """:class:`Modes` from a compiled eigen-solve: freqs (k,) Hz ascending; W (n, c) whitened
    shapes whose column j belongs to mode owner[j] (default: one column per mode); V (n_full, c)
    full-coordinate shapes or None.  A simple mode's columns are one complex direction: its
    first, normalised.  Each cluster of p repeated modes gets the p leading left singular
    vectors of its columns (an M-orthonormal basis of its eigenspace); V follows."""
    f = np.asarray(freqs, float)
    W = np.asarray(W)
    owner = np.arange(W.shape[1]) if owner is None else np.asarray(owner)
    ids = clusters(f, rtol)
    first = np.full(len(f), -1)
    cols_ok = np.flatnonzero((owner >= 0) & (owner < len(f)))[::-1]
    first[owner[cols_ok]] = cols_ok
    norm = np.linalg.norm(W[:, first], axis=0)
    scale = 1.0 / np.where(norm > 0, norm, 1.0)
    Wb = W[:, first] * scale
    Vb = None if V is None else np.asarray(V)[:, first] * scale
    size = np.bincount(ids)
    for c in np.flatnonzero(size > 1):
        members = np.flatnonzero(ids == c)
        cols = np.flatnonzero(np.isin(owner, members))
        U, sv, Vh = np.linalg.svd(W[:, cols], full_matrices=False)
        p = len(members)
        C = Vh.conj().T[:, :p] / np.where(sv[:p] > 0, sv[:p], 1.0)  # (cols, p): W[:, cols] @ C = U[:, :p]
        Wb[:, members] = U[:, :p]
        if Vb is not None:
            Vb[:, members] = np.asarray(V)[:, cols] @ C
    return Modes(f, Wb.astype(complex), ids, None if Vb is None else Vb.astype(complex))


def localise(modes: Modes, blocks: np.ndarray) -> None:
    """Rotate each cluster of repeated modes (in place) to the basis that concentrates each member
    in as few coordinate blocks as the eigenspace allows (``blocks`` (n_full,): an id per full
    coordinate, e.g. one per span and body; needs modes.V): the eigenvectors, within the
    cluster, of sum_b w_b |V_b|^2 with distinct weights w_b."""
    if modes.V is None:
        return
    w = np.modf(0.6180339887498949 * (np.asarray(blocks) + 1.0))[0] + 1.0  # distinct weights in (1, 2)
    for c in np.unique(modes.cluster):
        members = np.flatnonzero(modes.cluster == c)
        if len(members) < 2:
            continue
        Vc = modes.V[:, members]
        H = Vc.conj().T @ (w[:, None] * Vc)
        _, R = np.linalg.eigh(0.5 * (H + H.conj().T))
        modes.rotate(members, R)


class Tracker:
    """Curves followed step by step: ``step(modes)`` -> (index, mac) per curve.

    reference: :class:`Modes` whose members are the first curves (e.g. the nominal scene of a
    sweep); otherwise the first step's modes start the curves.  Curves are numbered in order of
    appearance (the first ones in ascending frequency); ``index[c]`` is curve c's mode at this
    step (-1: not seen), ``mac[c]`` its MAC with the curve's previous shape (NaN if not seen).
    ``step`` rotates repeated modes of ``modes`` in place (Procrustes), so labels computed from
    them afterwards follow the curves.
    """

    def __init__(self, reference: Modes | None = None, min_mac: float = MIN_MAC):
        self.min_mac = min_mac
        self.P: np.ndarray | None = None  # (n, curves): last unit whitened shape of each curve
        self.age = np.zeros(0, int)  # steps since each curve was last seen
        if reference is not None:
            self.P = np.array(reference.W, complex)
            self.age = np.zeros(self.P.shape[1], int)

    @property
    def n_curves(self) -> int:
        return 0 if self.P is None else self.P.shape[1]

    def skip(self) -> None:
        """A step without modes (unstable, no equilibrium): every curve ages."""
        self.age = self.age + 1

    def step(self, modes: Modes) -> tuple[np.ndarray, np.ndarray]:
        """Match ``modes`` (one step) to the curves; new curves for unmatched modes."""
        m = len(modes.freqs)
        index = np.full(self.n_curves, -1)
        mac = np.full(self.n_curves, np.nan)
        if self.n_curves:
            P = self.P
            single = np.abs(P.conj().T @ modes.W) ** 2  # (curves, modes)
            starts = np.flatnonzero(np.r_[True, np.diff(modes.cluster) != 0])  # clusters are contiguous
            sub = np.add.reduceat(single, starts, axis=1)[:, np.searchsorted(starts, np.arange(m), "right") - 1]
            rows, cols = linear_sum_assignment(sub - _AGE_PENALTY * self.age[:, None], maximize=True)
            keep = sub[rows, cols] >= self.min_mac
            rows, cols = rows[keep], cols[keep]
            index[rows] = cols
            size = np.bincount(modes.cluster)
            for c in np.unique(modes.cluster[cols][size[modes.cluster[cols]] > 1]):
                # a repeated mode: rotate the eigenspace's basis to the matched curves' shapes
                members = np.flatnonzero(modes.cluster == c)
                curves = rows[modes.cluster[cols] == c]
                U, _, Vh = np.linalg.svd(modes.W[:, members].conj().T @ P[:, curves])
                a = len(curves)
                modes.rotate(members, np.concatenate([U[:, :a] @ Vh, U[:, a:]], axis=1))
                index[curves] = members[:a]
            mac[rows] = np.abs(np.sum(P[:, rows].conj() * modes.W[:, index[rows]], axis=0)) ** 2
        new = np.setdiff1d(np.arange(m), index[index >= 0])
        index = np.concatenate([index, new]).astype(int)
        mac = np.concatenate([mac, np.full(len(new), np.nan)])
        P = modes.W[:, new] if self.P is None else np.concatenate([self.P, modes.W[:, new]], axis=1)
        seen = index >= 0
        P[:, seen] = modes.W[:, index[seen]]
        self.P = P
        self.age = np.where(seen, 0, np.concatenate([self.age, np.zeros(len(new), int)]) + 1)
        return index, mac


@dataclass
class Tracking:
    """Tracked curves over S steps: index (S, c) mode of curve c at each step (its index in that
    step's ascending frequencies; -1: not seen), freqs (S, c) Hz (NaN: not seen), mac (S, c) MAC
    with the curve's previous shape (NaN at a curve's first step and where not seen)."""

    index: np.ndarray
    freqs: np.ndarray
    mac: np.ndarray


def stack(steps: list[tuple[np.ndarray, np.ndarray]], freqs: list[np.ndarray | None]) -> Tracking:
    """A :class:`Tracking` from the (index, mac) of each :meth:`Tracker.step` (None for a skipped
    step) and each step's frequencies (None for a skipped step)."""
    c = max([len(s[0]) for s in steps if s is not None], default=0)
    S = len(steps)
    index = np.full((S, c), -1)
    mac = np.full((S, c), np.nan)
    F = np.full((S, c), np.nan)
    for k, (s, f) in enumerate(zip(steps, freqs)):
        if s is None:
            continue
        idx, m = s
        index[k, : len(idx)] = idx
        mac[k, : len(m)] = m
        ok = idx >= 0
        F[k, : len(idx)][ok] = np.asarray(f)[idx[ok]]
    return Tracking(index, F, mac)


def track(freqs, W, owner=None, valid=None, reference: Modes | None = None, rtol: float = RTOL_REPEATED,
          min_mac: float = MIN_MAC) -> Tracking:
    """Track modes over S steps (speeds or cases) in numpy.

    freqs (S, k) Hz ascending per step; W (S, n, c) mass-whitened shapes (columns of mode
    owner[j], owner (c,) or (S, c), default one column per mode); valid (S,) bool (False:
    skipped, e.g. unstable); reference: curves to match the first step to (default: the first
    valid step's modes).  Returns a :class:`Tracking`.
    """
    freqs = np.asarray(freqs, float)
    S = freqs.shape[0]
    valid = np.ones(S, bool) if valid is None else np.asarray(valid, bool)
    tracker = Tracker(reference, min_mac)
    steps, fs = [], []
    for k in range(S):
        if not valid[k] or not np.all(np.isfinite(freqs[k])):
            tracker.skip()
            steps.append(None)
            fs.append(None)
            continue
        own = None if owner is None else (np.asarray(owner)[k] if np.ndim(owner) == 2 else owner)
        modes = mode_basis(freqs[k], np.asarray(W[k]), own, rtol=rtol)
        steps.append(tracker.step(modes))
        fs.append(modes.freqs)
    return stack(steps, fs)


def reported(tracking: Tracking, n_report: int, rtol: float = RTOL_REPEATED) -> np.ndarray:
    """Curves worth reporting, in order: those among the ``n_report`` lowest modes at some step
    (a repeated mode straddling the n_report-th is included whole), ordered by the step where
    they first appear and their frequency there."""
    F = tracking.freqs
    keep = np.zeros(F.shape[1], bool)
    for k in range(F.shape[0]):
        f = np.sort(F[k][np.isfinite(F[k])])
        if f.size == 0:
            continue
        cut = f[min(n_report, f.size) - 1]
        keep |= np.isfinite(F[k]) & (F[k] <= cut + rtol * abs(cut))
    curves = np.flatnonzero(keep)
    first = np.array([np.flatnonzero(np.isfinite(F[:, c]))[0] for c in curves], int)
    at = F[first, curves]
    return curves[np.lexsort((at, first))]


def rank_masks(tracking: Tracking, curves, n: int) -> np.ndarray:
    """(S, n) bool: at each step, which of that step's modes (by index in its ascending order, the
    order of a compiled solve's frequencies) lie on ``curves`` -- e.g. the modes an objective
    watches, picked once by label, as per-step masks over sorted, differentiable frequencies."""
    out = np.zeros((tracking.index.shape[0], n), bool)
    for c in np.atleast_1d(curves):
        idx = tracking.index[:, c]
        ok = (idx >= 0) & (idx < n)
        out[np.flatnonzero(ok), idx[ok]] = True
    return out


def label_key(label: str) -> tuple:
    """What must stay the same along a curve for it to be the same mode: its kind and dominant
    member: ("transverse", "a-b") for "2nd transverse a-b + c-d", ("rotational", "alternator") for
    "1st rotational (alternator, crank)", the label itself otherwise.  The ordinal is left out:
    a travelling (gyroscopic) mode's half-waves are not sharp at speed, and a rotational mode's
    ordinal counts the rotational modes below it, which a veering elsewhere changes."""
    words = label.split()
    if len(words) >= 3 and words[1] in ("transverse", "longitudinal", "rotational"):
        return words[1], words[2].strip("(),")
    return (label,)


def label_runs(labels) -> list[list]:
    """Runs of one :func:`label_key` along a curve: labels (S,) per step (None: not seen).  A
    one-step excursion between two runs of one key is not a run.  Returns [key, first step,
    last step, label at the first step] per run."""
    runs: list[list] = []
    for k, lab in enumerate(labels):
        if lab is None:
            continue
        key = label_key(lab)
        if runs and runs[-1][0] == key:
            runs[-1][2] = k
        else:
            runs.append([key, k, k, lab])
    i = 1
    while i < len(runs) - 1:
        if runs[i][1] == runs[i][2] and runs[i - 1][0] == runs[i + 1][0]:
            runs[i - 1][2] = runs[i + 1][2]
            del runs[i : i + 2]
            i = max(1, i - 1)
        else:
            i += 1
    return runs


def follow_labels(labels) -> list:
    """A curve's labels (S,) per step (None: not seen) as they follow the mode: each step gets the
    label its run (:func:`label_runs`) has where it starts, so the label changes only where the
    mode's kind or dominant member does (a veering), and keeps the ordinal read where the mode
    took that kind (at the lowest speed: a standing wave)."""
    out = [None] * len(labels)
    for _, first, last, lab in label_runs(labels):
        for k in range(first, last + 1):
            if labels[k] is not None:
                out[k] = lab
    return out


def label_changes(labels, at) -> list[dict]:
    """Where a curve's label changes kind or dominant member (:func:`label_runs`): labels (S,) per
    step (None: not seen), at (S,) the step values (e.g. rpm).  Returns a list of {"from": label,
    "to": label, "at": value at the first step with the new label, "after": value at the last
    step with the old one}."""
    runs = label_runs(labels)
    return [{"from": a[3], "to": b[3], "at": float(at[b[1]]), "after": float(at[a[2]])}
            for a, b in zip(runs, runs[1:])]
