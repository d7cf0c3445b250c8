"""The drive's structure: the installation record, spans and bodies, coordinate counts, which
pulleys are free, the drive pulley and the belt speed (units: SI)."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from beltjax.ancf import Section
from beltjax.scene import Scene, require_scene
from beltjax.drive.assembly import Drive, drive_of  # noqa: F401
from beltjax.drive.effects import GRAVITY  # noqa: F401  (m/s^2)


class Installation(NamedTuple):
    """The belt as installed (a pytree of arrays; see :func:`beltjax.statics.install`).

    arm_angle: tensioner arm angle theta_1 (rad; 0 without a tensioner);
    stretch: uniform stretch lam of the belt at installation (-);
    tension: installation tension (N); belt_length: unstretched belt length (m);
    centers (n, 2) m and radii (n,) m in route order; span_start, span_end (n, 2):
    tangent points (m); span_tangent (n, 2): unit vectors; span_length (n,) m:
    installed span lengths; wrap (n,) rad; creep (n,) m: the belt each wrapped arc has handed
    its exit span since the belt was installed (zero as installed; a running belt's steady
    state, :func:`beltjax.friction.arc_belt_moved`, set by :func:`beltjax.statics.equilibrium`).
    """

    arm_angle: jax.Array
    stretch: jax.Array
    tension: jax.Array
    belt_length: jax.Array
    centers: jax.Array
    radii: jax.Array
    span_start: jax.Array
    span_end: jax.Array
    span_tangent: jax.Array
    span_length: jax.Array
    wrap: jax.Array
    creep: jax.Array


def canonical(scene: Scene) -> Scene:
    """The scene without its file label and description, so that scenes differing only in
    numbers share one compiled function (a SceneError for what is not a scene)."""
    return dataclasses.replace(require_scene(scene), source="", description="")


def statics_scene(scene: Scene, at_t: float | None = None) -> Scene:
    """The part of a scene that statics and the modal analysis read, in one structure per drive
    (so that scenes differing only in their transient tables share one compiled statics): no
    file label, no ``[initial]``, ``[simulation]`` or ``[[span_load]]`` tables, and the
    ``[[torque]]`` loads merged into one steady moment per loaded pulley (N m), the sum of the
    means of the lasting loads (``at_t`` None: the operating point) or of the loads acting at
    time ``at_t`` (s: a transient's start).  Idempotent."""
    from beltjax.drive.forces import _window  # a load's time window, as the transients apply it
    from beltjax.scene.spec import Initial, Simulation

    def acting(load):
        if at_t is None:
            return load.t_end_s is None
        return float(_window(at_t, load.t_start_s, load.t_end_s)) > 0.5

    torques = []
    for name in dict.fromkeys(load.pulley for load in scene.torques):
        mine = [load for load in scene.torques if load.pulley == name]
        zero = 0.0 * jnp.asarray(mine[0].mean_Nm)
        mean = sum((load.mean_Nm for load in mine if acting(load)), zero)
        torques.append(dataclasses.replace(mine[0], mean_Nm=mean, amplitude_Nm=zero, frequency_hz=zero,
                                           phase_deg=zero, t_start_s=zero, t_end_s=None))
    return dataclasses.replace(scene, source="", description="", initial=Initial(), simulation=Simulation(),
                               span_loads=(), torques=tuple(torques))


def span_names(scene: Scene) -> list[str]:
    """Names of the spans in route order: "<from>-<to>" (span i leaves route entry i)."""
    return scene.route.span_names


def is_free(scene: Scene) -> list[bool]:
    """Per route entry: whether its rotation is an independent coordinate (not driven)."""
    return list(drive_of(scene).free)


def flexible(scene: Scene) -> bool:
    """True for the hybrid ANCF fidelity (span nodes with mass); False for the rotational
    (Newton-Euler) one, whose spans are massless axial bars (:mod:`beltjax.drive.spans`)."""
    return drive_of(scene).spans.massive


def span_elements(scene: Scene) -> int:
    """Elements per span in the full coordinates: the mesh (ancf) or 1 (rotational: a bar)."""
    return drive_of(scene).spans.elements


def n_rigid(scene: Scene) -> int:
    """Number of independent rigid-body coordinates (free pulley angles, then the layout's:
    the arm angle of a tensioner)."""
    return drive_of(scene).n_rigid


def n_independent(scene: Scene) -> int:
    """Number of independent coordinates of the drive."""
    return drive_of(scene).n_independent


def n_span_coordinates(scene: Scene) -> int:
    """Number of span coordinates at the head of the full vector (4 (N+1) per span)."""
    return drive_of(scene).n_span_coordinates


def n_full(scene: Scene) -> int:
    """Number of full coordinates (spans, then 3 per body)."""
    return drive_of(scene).n_full


def body_names(scene: Scene) -> list[str]:
    """Rigid bodies in the order of the full coordinates: route entries, then the layout's
    ("tensioner arm")."""
    return drive_of(scene).body_names


def static_dofs(scene: Scene) -> np.ndarray:
    """Independent coordinates solved for in statics: all but a free drive pulley's angle.

    A drive whose pulleys are all free turns as a rigid body at no cost (zero
    stiffness); statics holds the drive pulley (its reaction is the drive torque).
    """
    return drive_of(scene).static_dofs


def travel_follows_drive(scene: Scene) -> bool:
    """Whether a transient's belt travel follows the drive pulley's own rotation: when that
    pulley is free (no pulley of the route is driven, e.g. a crank turned by a [[torque]]).

    The belt then travels x = x_b(t) + s R phi_d (m: the nominal travel of
    :func:`belt_travel` plus the drive pulley's rim travel beyond it), its transport speed is
    c = s R theta_d' / lam, and every span end slides by its pulley's rim travel less x
    (:func:`full_coordinates`); otherwise x = x_b(t) is prescribed.
    """
    return drive_of(scene).travel_follows_drive


def travel_coordinate(scene: Scene) -> int:
    """Position in q_i of the drive pulley's angle when it is free (:func:`travel_follows_drive`)."""
    return drive_of(scene).travel_coordinate


def drive_pulley(scene: Scene) -> int:
    """Route index of the pulley whose speed sets the belt speed.

    The driven pulley (the first one in the file if several), else the first
    pulley of the file.
    """
    return drive_of(scene).drive_pulley


def belt_speed(scene: Scene, rpm=None):
    """Belt speed (m/s) at the drive pulley's speed ``rpm`` (default: its speed_rpm)."""
    p = scene.pulley(scene.route.order[drive_pulley(scene)])
    rpm = p.speed_rpm if rpm is None else rpm
    return jnp.abs(rpm) * (2 * jnp.pi / 60.0) * p.radius


def section(scene: Scene) -> Section:
    """The belt section (EA N, EI N m^2, rhoA kg/m)."""
    b = scene.belt
    return Section(b.EA, b.EI, b.rhoA)


def element_length(scene: Scene, inst: Installation):
    """Unstretched element length of each span (m), shape (n,)."""
    return inst.span_length / (inst.stretch * span_elements(scene))
