"""Sweep frequency columns that follow modes (used by :mod:`beltjax.sweep`).

A sweep's case function returns, with the frequencies, the mass-whitened shapes of a few
more modes than kept (:func:`beltjax.drive_modal.tracking_shapes`); :func:`track_chunk`
turns each chunk's shapes into frequency columns that follow the nominal scene's modes
(:func:`references`), at once where :func:`beltjax.mode_batch.match` can (from the projections
the compiled case made on the device), else by the tracker of :mod:`beltjax.mode_tracking` (the
shapes of those cases only fetched from the device), and drops the shapes, so memory stays that
of a few chunks.  Column k is the nominal's k-th mode in every case: an
engineer reading sweep.csv finds a mode in one column whatever its rank in a case.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from beltjax import campbell, mode_batch, mode_tracking
from beltjax.errors import BeltjaxError
from beltjax.scene import Scene

#: per-case mode shapes of a tracked batch (dropped once the chunk is tracked)
SHAPE_KEYS = ("modal_W", "modal_owner", "modal_proj", "campbell_W", "campbell_owner")
#: of those, the ones a chunk keeps on its device until the tracking asks for some cases'
DEVICE_KEYS = ("modal_W",)


def references(scene: Scene, outputs, modes: int, rpm=None) -> dict:
    """The nominal scene's modes that the frequency columns follow: {"modal": (Modes, labels) at
    the scene's speed, "campbell": (Modes, labels) at the lowest ``rpm``}, for the outputs asked
    (:func:`beltjax.campbell.reference_modes`); None for one whose nominal has no modes (its
    statics fail or it is unstable: the columns are then sorted per case)."""
    out = {}
    for o, speed in (("modal", None), ("campbell", None if rpm is None or not len(rpm) else float(rpm[0]))):
        if o in outputs:
            try:
                out[o] = campbell.reference_modes(scene, modes, speed)
            except BeltjaxError:
                out[o] = None
    return out


def track_chunk(out: dict[str, np.ndarray], refs: Mapping[str, Any], modes: int) -> dict[str, np.ndarray]:
    """Frequency columns of a chunk following the nominal's modes (``refs``, :func:`references`):
    column k of ``frequencies_hz`` is the nominal's k-th mode in each case, found by its shape
    (:class:`beltjax.mode_tracking.Tracker` seeded with the nominal's modes; NaN where no mode
    of the case matches it, MAC < MIN_MAC), ``mode_mac`` its MAC; ``campbell_hz`` follows the
    nominal's modes at the lowest speed into each case and then along its speeds
    (``campbell_mode_match``: the lowest MAC of a case).  Without a reference: the lowest
    ``modes`` sorted (modal) or tracked from the case's own lowest speed (campbell)."""
    if "modal_W" in out:
        F, W, own = out.pop("frequencies_hz"), out.pop("modal_W"), np.asarray(out.pop("modal_owner"))
        A = out.pop("modal_proj", None)
        ref = refs.get("modal")
        n = ref[0].freqs.size if ref else modes
        Ft, mac = np.full((len(F), n), np.nan), np.full((len(F), n), np.nan)
        done = np.zeros(len(F), bool)
        if ref is not None:  # every case whose match is certain at once (mode_batch), the rest one by one
            A = mode_batch.projections(np.asarray(W), ref[0].W) if A is None else A
            Ft, mac, done = mode_batch.match(F, A, own)
        rest = np.flatnonzero(~done & np.all(np.isfinite(F), axis=1))  # failed or unstable cases: nothing to fetch
        W = dict(zip(rest.tolist(), np.asarray(W[rest]))) if rest.size else {}  # from the device: these cases' only
        for i in rest:
            if not (np.all(np.isfinite(F[i])) and np.all(np.isfinite(W[i]))):
                continue
            if ref is None:
                Ft[i] = F[i, :n]
                continue
            md = mode_tracking.mode_basis(F[i], W[i], own[i])
            index, m = mode_tracking.Tracker(ref[0]).step(md)
            found = index[:n] >= 0
            Ft[i, found], mac[i] = md.freqs[index[:n][found]], m[:n]
        out["frequencies_hz"], out["mode_mac"] = Ft, mac
    if "campbell_W" in out:
        F, W, own, ok = out.pop("campbell_hz"), out.pop("campbell_W"), out.pop("campbell_owner"), out["campbell_stable"]
        ref = refs.get("campbell")
        n = ref[0].freqs.size if ref else modes
        Ft, match = np.full((*F.shape[:2], n), np.nan), np.full(len(F), np.nan)
        for i in range(len(F)):
            tracker, low = mode_tracking.Tracker(ref[0] if ref else None), 1.0
            for j in range(F.shape[1]):
                if not (ok[i, j] and np.all(np.isfinite(F[i, j])) and np.all(np.isfinite(W[i, j]))):
                    tracker.skip()
                    continue
                md = mode_tracking.mode_basis(F[i, j], W[i, j], own[i, j])
                index, m = tracker.step(md)
                found = index[:n] >= 0
                Ft[i, j, found] = md.freqs[index[:n][found]]
                low = min(low, float(np.min(np.where(found, np.nan_to_num(m[:n], nan=1.0), 0.0))))
            match[i] = low if np.any(ok[i]) else np.nan
        out["campbell_hz"], out["campbell_mode_match"] = Ft, match
    return out
