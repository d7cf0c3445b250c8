"""Outputs at a state: span tension profiles and tensions (N), hub forces (N), span lengths (m)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from beltjax import ancf, span
from beltjax.scene import Scene
from beltjax.drive.topology import Installation, element_length, flexible
from beltjax.drive.kinematics import split_full
from beltjax.drive.forces import span_forces
from beltjax.drive.equations import transport_speed


def span_tension_profile(e, EA, Le, N):
    """Axial force EA eps |r'| (N) at each element's midpoint of a span, shape (N,)."""
    idx = span.element_index(N)

    def one(ee):
        rp = ancf.slope(ee, 0.5, Le)
        lam = jnp.sqrt(rp @ rp)
        return ancf.axial_force(lam, EA)

    return jax.vmap(one)(e[idx])


def span_tensions(q, scene: Scene, inst: Installation):
    """Mean axial force of each span (N), route order."""
    E, _ = split_full(q, scene)
    Le = element_length(scene, inst)
    if not flexible(scene):
        lam = jnp.linalg.norm(E[:, 4:6] - E[:, 0:2], axis=1) / Le
        return ancf.axial_force(lam, scene.belt.EA)
    N = scene.model.elements_per_span
    return jnp.stack([jnp.mean(span_tension_profile(E[s], scene.belt.EA, Le[s], N)) for s in range(E.shape[0])])


def hub_forces(q, scene: Scene, inst: Installation, speed=0.0):
    """Force of the belt on each route entry's hub, (n, 2) N, at a steady state.

    The force a span exerts on the pulley holding its end node is the span's
    generalized force on that node's position (elastic, transport momentum flux
    and weight as listed); the hub force sums both spans touching the pulley.
    """
    E, _ = split_full(q, scene)
    n = E.shape[0]
    c = transport_speed(scene, inst, speed)
    out = jnp.zeros((n, 2), dtype=q.dtype)
    for s in range(n):
        f = span_forces(E[s], jnp.zeros_like(E[s]), s, scene, inst, c)
        out = out.at[s].add(f[:2]).at[(s + 1) % n].add(f[-4:-2])
    return out


def full_span_lengths(q, scene: Scene):
    """Chord length of each span between its end nodes (m), route order."""
    E, _ = split_full(q, scene)
    return jnp.linalg.norm(E[:, -4:-2] - E[:, :2], axis=1)
