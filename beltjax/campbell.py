"""Campbell diagrams: natural frequencies of a drive against the drive pulley's speed.

For every speed the steady-motion statics and the gyroscopic modal problem of
:mod:`beltjax.drive_modal` are solved in one compiled function, vmapped over the
speeds (in chunks, to bound memory), with the mode shapes.  The modes are *tracked*
across speeds by their shapes (:mod:`beltjax.mode_tracking`: mass-weighted MAC with
the previous speed, repeated pairs matched as subspaces), so each curve of the
diagram is one mode; every curve is labelled from its own shape at every speed, so
a crossing carries the label of the mode that crosses, and a curve whose label
changes along the way (a veering: two modes exchanging their shapes) is reported.
Excitation orders are multiples of the drive pulley's rotation frequency
(``order * rpm / 60`` Hz); a crossing is where a mode's frequency equals an order
line, located by linear interpolation between speeds.
:func:`campbell_frequencies` gives the sorted frequencies alone (no shapes, faster).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import drive, drive_modal, mode_tracking, statics
from beltjax.scene import Scene
from beltjax.drive.effects import effects_of

DEFAULT_ORDERS = (1.0, 2.0, 3.0)


@partial(jax.jit, static_argnames=("n_modes",))
def _batch(scene: Scene, speeds, n_modes: int):
    def one(v):
        # speed stepping from rest: robust up to high speeds (the steady-state statics moves
        # the tensioner arm), cheap next to the eigen-solve
        m = drive_modal.at_speed(scene, v, steps=statics.SPEED_STEPS)
        stable = m.stable & ~m.supercritical  # past the critical speed: unstable
        return m.freqs[:n_modes], stable, m.converged

    return jax.vmap(one)(speeds)


def campbell_frequencies(scene: Scene, rpm, n_modes: int = 20, chunk: int = 32, progress=None):
    """Frequencies (Hz) of the lowest ``n_modes`` modes at each drive-pulley speed.

    rpm: (n,) speeds of the drive pulley (rpm).  Returns (freqs (n, n_modes) with
    NaN where the drive is unstable, past its critical speed (:mod:`beltjax.critical`) or the
    statics failed, stable (n,) bool (False past the critical speed), converged (n,) bool).
    progress: optional callable(done, total) called after each chunk.
    """
    scene = drive.canonical(scene)
    rpm = np.asarray(rpm, dtype=float)
    n_modes = min(n_modes, drive.n_independent(scene))
    speeds = np.asarray(drive.belt_speed(scene, jnp.asarray(rpm)))
    out_f, out_ok, out_conv = [], [], []
    for start in range(0, len(speeds), chunk):
        part = speeds[start : start + chunk]
        size = chunk if len(speeds) > 8 else 8  # few batch shapes: few compilations
        pad = size - len(part)
        padded = np.concatenate([part, np.full(pad, part[-1])]) if pad else part
        f, ok, conv = _batch(scene, jnp.asarray(padded), n_modes)
        out_f.append(np.asarray(f)[: len(part)])
        out_ok.append(np.asarray(ok)[: len(part)])
        out_conv.append(np.asarray(conv)[: len(part)])
        if progress is not None:
            progress(min(start + chunk, len(speeds)), len(speeds))
    f = np.concatenate(out_f)
    ok = np.concatenate(out_ok)
    conv = np.concatenate(out_conv)
    f[~(ok & conv)] = np.nan
    return f, ok, conv


@partial(jax.jit, static_argnames=("k",))
def _tracked_batch(scene: Scene, speeds, k: int):
    gyro = effects_of(scene).moving_belt

    def one(v):
        m = drive_modal.at_speed(scene, v, steps=statics.SPEED_STEPS, gyroscopic=gyro, track=k, full=True)
        out = dict(m.tracking)
        out["stable"] = out["stable"] & ~m.supercritical  # past the critical speed
        out["converged"] = m.converged
        return out

    return jax.vmap(one)(speeds)


def coordinate_blocks(scene: Scene) -> np.ndarray:
    """(n_full,) id of the span or body of each full coordinate (for :func:`beltjax.mode_tracking.localise`)."""
    n_spans = len(drive.span_names(scene))
    n_bodies = len(drive.body_names(scene))
    ns = (drive.n_full(scene) - 3 * n_bodies) // n_spans
    return np.concatenate([np.repeat(np.arange(n_spans), ns), n_spans + np.repeat(np.arange(n_bodies), 3)])


def reference_modes(scene: Scene, n_modes: int, rpm: float | None = None):
    """The lowest ``n_modes`` modes of ``scene`` at drive-pulley speed ``rpm`` (default its own
    speed_rpm) as curves to track other cases or speeds to: (:class:`beltjax.mode_tracking.Modes`,
    labels), repeated pairs localised (one span each where they can be) and labelled from those
    shapes; None when the drive is unstable there.  Raises the statics' one-line errors."""
    scene = drive.canonical(scene)
    v = float(drive.belt_speed(scene, rpm)) if rpm is not None else float(drive.belt_speed(scene))
    st = statics.analyse_statics(scene, v, with_unloaded=False)
    out = drive_modal.modes_at(scene, jnp.asarray(st.qi), st.inst, v, effects_of(scene).moving_belt and v != 0.0)
    if not bool(out["stable"]):
        return None
    k = min(n_modes, drive.n_independent(scene))
    X = np.asarray(out["shapes"])[:, :k]
    W = np.linalg.cholesky(np.asarray(out["M"])).T @ X
    modes = mode_tracking.mode_basis(np.asarray(out["freqs"])[:k], W, V=np.asarray(out["J"]) @ X)
    mode_tracking.localise(modes, coordinate_blocks(scene))
    arrays = drive_modal.label_arrays(scene, st.inst)
    return modes, drive_modal.label_full(modes.freqs, modes.V, scene, arrays)[0]


@dataclass
class TrackedModes:
    """Modes tracked over speeds (see :func:`campbell_modes`): tracking (a
    :class:`beltjax.mode_tracking.Tracking` of every curve), labels (n, curves) per speed and
    curve (None where the curve is not seen), stable (n,), converged (n,), n_computed (modes
    computed per speed)."""

    tracking: mode_tracking.Tracking
    labels: list
    stable: np.ndarray
    converged: np.ndarray
    n_computed: int


def campbell_modes(scene: Scene, rpm, n_modes: int = 20, chunk: int = 32, progress=None) -> TrackedModes:
    """Modes at each drive-pulley speed ``rpm`` (rpm, ascending), tracked across speeds by their shapes.

    Computes :func:`beltjax.mode_tracking.n_computed` modes per speed (a margin above
    ``n_modes``) in compiled, vmapped chunks, then tracks them in numpy
    (:class:`beltjax.mode_tracking.Tracker`) and labels each mode from its own (tracked)
    shape.  Speeds where the drive is unstable or the statics failed are gaps.
    progress: optional callable(done, total) called after each chunk.
    """
    scene = drive.canonical(scene)
    rpm = np.asarray(rpm, dtype=float)
    k = mode_tracking.n_computed(n_modes, drive.n_independent(scene))
    speeds = np.asarray(drive.belt_speed(scene, jnp.asarray(rpm)))
    blocks = coordinate_blocks(scene)
    tracker = mode_tracking.Tracker()
    steps, freqs, labels, oks, convs = [], [], [], [], []
    for start in range(0, len(speeds), chunk):
        part = speeds[start : start + chunk]
        size = chunk if len(speeds) > 8 else 8  # few batch shapes: few compilations
        pad = size - len(part)
        padded = np.concatenate([part, np.full(pad, part[-1])]) if pad else part
        out = jax.tree.map(np.asarray, _tracked_batch(scene, jnp.asarray(padded), k))
        for i in range(len(part)):
            ok, conv = bool(out["stable"][i]), bool(out["converged"][i])
            oks.append(ok)
            convs.append(conv)
            f = out["freqs"][i]
            if not (ok and conv and np.all(np.isfinite(f)) and np.all(np.isfinite(out["W"][i]))):
                tracker.skip()
                steps.append(None)
                freqs.append(None)
                labels.append(None)
                continue
            modes = mode_tracking.mode_basis(f, out["W"][i], out["owner"][i], out["V"][i])
            if tracker.n_curves == 0:
                mode_tracking.localise(modes, blocks)
            steps.append(tracker.step(modes))
            freqs.append(modes.freqs)
            arrays = {key: out[key][i] for key in ("Le", "tangent", "body_mass")}
            labels.append(drive_modal.label_full(modes.freqs, modes.V, scene, arrays)[0])
        if progress is not None:
            progress(min(start + chunk, len(speeds)), len(speeds))
    tracking = mode_tracking.stack(steps, freqs)
    along = [[None if lab is None or j < 0 else lab[j] for j in idx] for lab, idx in zip(labels, tracking.index)]
    return TrackedModes(tracking, along, np.asarray(oks), np.asarray(convs), k)


def crossings(rpm, freqs, orders=DEFAULT_ORDERS, labels=None, labels_along=None):
    """Speeds where a mode meets an order line: list of dicts (mode, label, order, rpm, frequency_hz).

    rpm (n,), freqs (n, m) Hz (a column per mode: tracked curves, or sorted ranks); orders:
    excitation orders (multiples of the drive pulley's rotation frequency); labels (m,) per
    column.  labels_along (n, m): the label of each column's mode at each speed (from its
    shape there; None where not known): a crossing then carries the label at the nearer of
    the two speeds around it, and the column's label as ``curve_label``.  Rigid-body modes
    (0 Hz) are skipped.
    """
    rpm = np.asarray(rpm, float)
    out = []
    for k in orders:
        line = k * rpm / 60.0
        for m in range(freqs.shape[1]):
            f = freqs[:, m]
            if np.all(~np.isfinite(f)) or np.nanmax(f) < drive_modal.RIGID_HZ:
                continue
            g = f - line
            for i in range(len(rpm) - 1):
                a, b = g[i], g[i + 1]
                same_side = np.sign(a) * np.sign(b) > 0  # (a * b overflows for huge order lines)
                if not (np.isfinite(a) and np.isfinite(b)) or a == b or same_side or (a == 0 and i > 0):
                    continue
                s = a / (a - b)
                r = rpm[i] + s * (rpm[i + 1] - rpm[i])
                c = dict(mode=m + 1, label=None if labels is None else labels[m], order=float(k), rpm=float(r),
                         frequency_hz=float(k * r / 60.0))
                if labels_along is not None:
                    near = (i, i + 1) if s <= 0.5 else (i + 1, i)
                    here = [labels_along[j][m] for j in near if labels_along[j][m] is not None]
                    c["curve_label"] = c["label"]
                    c["label"] = here[0] if here else c["label"]
                out.append(c)
    return sorted(out, key=lambda c: (c["rpm"], c["mode"]))


@dataclass
class CampbellResult:
    """A Campbell diagram.

    rpm (n,); frequencies_hz (n, m): one column per *tracked mode* (curve), followed across
    speeds by its shape (NaN: unstable, no equilibrium, or the mode outside the computed
    modes there), the columns in ascending frequency at the lowest speed (curves that enter
    later follow); labels (m,): each curve's label at the lowest speed where it is seen;
    labels_along (n, m): its label at every speed (None where not seen), read from its shape
    there: kind and dominant span or body at every speed, the ordinal where the curve takes
    that kind (:func:`beltjax.mode_tracking.follow_labels`); label_changes: where a curve's
    label changes kind or dominant member (a veering: list of dicts mode, label, from, to,
    rpm, after_rpm); crossings (list of dicts, each with the
    label at the crossing and the curve's label); mac (n, m): MAC of each curve's shape with
    its shape at the previous speed; orders; stable, converged (n,) bool; drive pulley name;
    tracked: False for a diagram of sorted frequencies (columns = ranks); n_computed: modes
    computed per speed.
    """

    rpm: np.ndarray
    frequencies_hz: np.ndarray
    labels: list[str]
    orders: tuple
    crossings: list
    stable: np.ndarray
    converged: np.ndarray
    drive_pulley: str
    transport: bool
    labels_along: list | None = None
    label_changes: list = field(default_factory=list)
    mac: np.ndarray | None = None
    tracked: bool = False
    n_computed: int | None = None

    def uncertain(self) -> list[dict]:
        """Steps where a curve's MAC with its previous shape is below
        :data:`beltjax.mode_tracking.UNCERTAIN_MAC`: (mode, rpm, mac) -- the speed step does not
        resolve how the shapes change there."""
        if self.mac is None:
            return []
        bad = np.argwhere(self.mac < mode_tracking.UNCERTAIN_MAC)
        return [dict(mode=int(m) + 1, rpm=float(self.rpm[i]), mac=round(float(self.mac[i, m]), 4)) for i, m in bad]

    def to_json(self) -> dict:
        """campbell.json contents."""
        meaning = ("one column per tracked mode (curve), in the order of labels: a mode keeps its column across "
                   "speeds, followed by its mode shape (mass-weighted MAC with the previous speed); null where the "
                   "drive is unstable, has no equilibrium, or the mode is outside the computed modes"
                   if self.tracked else "the modes at each speed sorted by frequency (columns are ranks, not modes)")
        out = {
            "drive_pulley": self.drive_pulley,
            "transport_effect": self.transport,
            "rpm": [float(r) for r in self.rpm],
            "frequencies_hz": [[None if not np.isfinite(x) else float(x) for x in row] for row in self.frequencies_hz],
            "frequencies_meaning": meaning,
            "labels": self.labels,
            "orders": [float(k) for k in self.orders],
            "stable": [bool(s) for s in self.stable],
            "statics_converged": [bool(s) for s in self.converged],
            "crossings": self.crossings,
        }
        if self.tracked:
            out["label_changes"] = self.label_changes
            out["tracking"] = {
                "modes_computed_per_speed": self.n_computed,
                "min_mac_per_mode": [None if not np.any(np.isfinite(c)) else round(float(np.nanmin(c)), 4)
                                     for c in self.mac.T],
                "uncertain_steps": self.uncertain(),
            }
        return out


def analyse_campbell(scene: Scene, rpm, orders=DEFAULT_ORDERS, n_modes: int = 20, progress=None) -> CampbellResult:
    """Campbell diagram of a drive over drive-pulley speeds ``rpm`` with order lines ``orders``.

    Runs the statics at the lowest speed first (its one-line errors apply).  The modes are
    tracked across speeds (:func:`campbell_modes`); the result holds every mode that is among
    the lowest ``n_modes`` at some speed (so possibly more than n_modes curves; a repeated
    pair is kept whole), each curve labelled from its shape at every speed.  The scene is
    checked as a scene file is; a speed outside the range of ``drive.rpm`` (NaN, infinite,
    negative, above 1e6), an order outside that of ``fluctuation.order`` (:mod:`beltjax.schema`:
    (0, 1000]), or n_modes below 1 is a one-line
    :class:`beltjax.errors.BeltjaxError` naming the argument.
    """
    from beltjax import schema, validate
    from beltjax.errors import BeltjaxError

    validate.check_scene(scene)
    rpm = np.sort(validate.speeds(rpm, "rpm", "drive.rpm"))
    o = np.asarray(orders, dtype=float).reshape(-1) if np.ndim(orders) <= 1 else np.zeros(0)
    if o.size == 0 or not np.all(np.isfinite(o) & (o > 0)):
        raise BeltjaxError(f"expected positive finite excitation orders, got {orders!r}", "orders")
    order = schema.FIELDS["fluctuation.order"]  # multiples of the drive pulley's speed, as a scene's
    for i, k in enumerate(o):
        if msg := schema.problem(order, k):
            raise BeltjaxError(msg, f"orders[{i}]")
    validate.count(n_modes, "n_modes")
    statics.analyse_statics(scene, float(drive.belt_speed(scene, rpm[0])), allow_supercritical=True, with_unloaded=False)
    tm = campbell_modes(scene, rpm, n_modes, progress=progress)
    t = tm.tracking
    curves = mode_tracking.reported(t, n_modes)
    F = t.freqs[:, curves]
    along = [mode_tracking.follow_labels([row[c] for row in tm.labels]) for c in curves]
    along = [list(row) for row in zip(*along)] if along else [[] for _ in rpm]
    labels = [next((row[j] for row in along if row[j] is not None), f"mode {j + 1}") for j in range(len(curves))]
    changes = []
    for j in range(len(curves)):
        for c in mode_tracking.label_changes([row[j] for row in along], rpm):
            changes.append(dict(mode=j + 1, label=labels[j], **{k: c[k] for k in ("from", "to")},
                                rpm=c["at"], after_rpm=c["after"]))
    return CampbellResult(
        rpm=rpm,
        frequencies_hz=F,
        labels=labels,
        orders=tuple(float(k) for k in orders),
        crossings=crossings(rpm, F, orders, labels, along),
        stable=tm.stable,
        converged=tm.converged,
        drive_pulley=scene.route.order[drive.drive_pulley(scene)],
        transport=effects_of(scene).moving_belt,
        labels_along=along,
        label_changes=sorted(changes, key=lambda c: (c["rpm"], c["mode"])),
        mac=t.mac[:, curves],
        tracked=True,
        n_computed=tm.n_computed,
    )
