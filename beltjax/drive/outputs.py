"""Outputs at a state: span tension profiles and tensions (N), hub forces (N), span lengths (m)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from beltjax.scene import Scene
from beltjax.drive.topology import Installation, element_length
from beltjax.drive.spans import spans_of, tension_profile as span_tension_profile  # noqa: F401
from beltjax.drive.kinematics import split_full
from beltjax.drive.forces import span_forces
from beltjax.drive.equations import transport_speed


def span_tensions(q, scene: Scene, inst: Installation):
    """Mean axial force of each span (N), route order."""
    E, _ = split_full(q, scene)
    return spans_of(scene).tensions(E, scene.belt.EA, element_length(scene, inst))


def hub_forces(q, scene: Scene, inst: Installation, speed=0.0):
    """Force of the belt on each route entry's hub, (n, 2) N, at a steady state.

    The force a span exerts on the pulley holding its end node is the span's
    generalized force on that node's position (elastic, transport momentum flux
    and weight as listed); the hub force sums both spans touching the pulley.
    """
    E, _ = split_full(q, scene)
    c = transport_speed(scene, inst, speed)
    # one span's forces mapped over the span index: the program holds them once, not once per span
    f = jax.vmap(lambda e, s: span_forces(e, jnp.zeros_like(e), s, scene, inst, c))(E, jnp.arange(E.shape[0]))
    return f[:, :2] + jnp.roll(f[:, -4:-2], 1, axis=0)  # pulley k: the start of span k, the end of span k - 1


def full_span_lengths(q, scene: Scene):
    """Chord length of each span between its end nodes (m), route order."""
    E, _ = split_full(q, scene)
    return jnp.linalg.norm(E[:, -4:-2] - E[:, :2], axis=1)
