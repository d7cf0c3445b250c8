"""Campbell diagrams: natural frequencies of a drive against the drive pulley's speed.

For every speed the steady-motion statics and the gyroscopic modal problem of
:mod:`beltjax.drive_modal` are solved in one compiled function, vmapped over the
speeds (in chunks, to bound memory).  Frequencies are sorted at each speed (no
mode tracking); the labels are those of the modes at the lowest speed of the
sweep.  Excitation orders are multiples of the drive pulley's rotation
frequency (``order * rpm / 60`` Hz); a crossing is where a mode's frequency
equals an order line, located by linear interpolation between speeds.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import critical, drive, drive_modal, statics
from beltjax.scene import Scene

DEFAULT_ORDERS = (1.0, 2.0, 3.0)


@partial(jax.jit, static_argnames=("n_modes",))
def _batch(scene: Scene, speeds, n_modes: int):
    gyro = scene.model.has("transport")
    nr = drive_modal.n_rigid_modes(scene)

    def one(v):
        # speed stepping from rest: robust up to high speeds (the steady-state statics moves
        # the tensioner arm), cheap next to the eigen-solve
        qi, inst, info = statics.equilibrium(scene, speed=v, steps=4)
        M, G, K = drive_modal.linearise(qi, scene, inst, v)
        stable, f = drive_modal.frequencies_from_matrices(M, G, K, nr, gyro, drive_modal.rigid_mode(scene, inst))
        stable = stable & ~critical.supercritical(scene, qi, inst, v)  # past the critical speed: unstable
        return f[:n_modes], stable, info[0] > 0.5

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


def crossings(rpm, freqs, orders=DEFAULT_ORDERS, labels=None):
    """Speeds where a mode meets an order line: list of dicts (mode, label, order, rpm, frequency_hz).

    rpm (n,), freqs (n, m) Hz; orders: excitation orders (multiples of the drive
    pulley's rotation frequency).  Rigid-body modes (0 Hz) are skipped.
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
                if not (np.isfinite(a) and np.isfinite(b)) or a == b or a * b > 0 or (a == 0 and i > 0):
                    continue
                s = a / (a - b)
                r = rpm[i] + s * (rpm[i + 1] - rpm[i])
                out.append(
                    dict(
                        mode=m + 1,
                        label=None if labels is None else labels[m],
                        order=float(k),
                        rpm=float(r),
                        frequency_hz=float(k * r / 60.0),
                    )
                )
    return sorted(out, key=lambda c: (c["rpm"], c["mode"]))


@dataclass
class CampbellResult:
    """A Campbell diagram: rpm (n,), frequencies_hz (n, m) (NaN: unstable), labels (m, at the
    lowest speed), orders, crossings (list of dicts), stable (n,) bool, drive pulley name."""

    rpm: np.ndarray
    frequencies_hz: np.ndarray
    labels: list[str]
    orders: tuple
    crossings: list
    stable: np.ndarray
    converged: np.ndarray
    drive_pulley: str
    transport: bool

    def to_json(self) -> dict:
        """campbell.json contents."""
        return {
            "drive_pulley": self.drive_pulley,
            "transport_effect": self.transport,
            "rpm": [float(r) for r in self.rpm],
            "frequencies_hz": [[None if not np.isfinite(x) else float(x) for x in row] for row in self.frequencies_hz],
            "labels": self.labels,
            "orders": [float(k) for k in self.orders],
            "stable": [bool(s) for s in self.stable],
            "statics_converged": [bool(s) for s in self.converged],
            "crossings": self.crossings,
        }


def analyse_campbell(scene: Scene, rpm, orders=DEFAULT_ORDERS, n_modes: int = 20, progress=None) -> CampbellResult:
    """Campbell diagram of a drive over drive-pulley speeds ``rpm`` with order lines ``orders``.

    Runs the statics at the lowest speed first (its one-line errors apply) and
    labels the modes there.  The scene is checked as a scene file is; a speed that is NaN,
    infinite or negative, an order that is not positive and finite, or n_modes below 1 is a
    one-line :class:`beltjax.errors.BeltjaxError` naming the argument.
    """
    from beltjax import validate
    from beltjax.errors import BeltjaxError

    validate.check_scene(scene)
    rpm = np.sort(validate.speeds(rpm, "rpm", "drive.rpm"))
    o = np.asarray(orders, dtype=float).reshape(-1) if np.ndim(orders) <= 1 else np.zeros(0)
    if o.size == 0 or not np.all(np.isfinite(o) & (o > 0)):
        raise BeltjaxError(f"expected positive finite excitation orders, got {orders!r}", "orders")
    if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)) or n_modes < 1:
        raise BeltjaxError(f"must be an integer >= 1, got {n_modes!r}", "n_modes")
    v0 = float(drive.belt_speed(scene, rpm[0]))
    base = drive_modal.analyse_modes(scene, v0)
    f, ok, conv = campbell_frequencies(scene, rpm, n_modes, progress=progress)
    labels = list(base.labels[: f.shape[1]]) if base.stable else [f"mode {i + 1}" for i in range(f.shape[1])]
    return CampbellResult(
        rpm=rpm,
        frequencies_hz=f,
        labels=labels,
        orders=tuple(float(k) for k in orders),
        crossings=crossings(rpm, f, orders, labels),
        stable=ok,
        converged=conv,
        drive_pulley=scene.route.order[drive.drive_pulley(scene)],
        transport=scene.model.has("transport"),
    )
