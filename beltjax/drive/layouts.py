"""Layout components: where the pulley centres are.  A drive's layout is chosen once by
:func:`layout_of`:

- :class:`FixedCentres`: every pulley on a fixed bearing; the spans keep their installed
  tangent points and directions (their ends slide along them as the pulleys turn);
- :class:`TensionerArm`: an automatic tensioner, a rigid arm on a pivot carrying the idler,
  with a torsion spring: one more independent coordinate (the arm angle, rad) and one more
  body; the tangent points follow the moved layout exactly.

Both give the same interface to the kinematic map and the body forces: the arm angle from
the rigid coordinates, the pulley centres and radii, the span tangent lines and how far each
turned, the arm's body coordinates, masses and spring moment.  Units: m, rad, kg, N m.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from beltjax import geometry
from beltjax.drive import pivot
from beltjax.scene.spec import TENSIONER


class Layout(eqx.Module):
    """The interface of a layout component (see the module docstring)."""

    #: independent coordinates it adds (after the free pulleys' angles)
    coordinates: ClassVar[int] = 0
    #: the bodies it adds after the route entries (each also a bearing whose reaction is reported)
    body_names: ClassVar[tuple[str, ...]] = ()

    def arm_angle(self, rigid, inst):
        """The arm angle theta (rad) for the rigid independent coordinates ``rigid``."""
        return inst.arm_angle

    def centers(self, theta, scene, inst, shift=None):
        """Pulley centres (n, 2) m and radii (n,) m in route order at arm angle theta (rad), each
        bearing moved by ``shift`` ((n_reaction_points, 2) m: route entries, then the pivot)."""
        raise NotImplementedError

    def tangents(self, centers, radii, scene, inst):
        """The span tangent lines (:class:`beltjax.geometry.TangentLine`) of the layout with
        these centres (m), and how far each span's direction turned from the installed one,
        dpsi (n,) rad CCW."""
        raise NotImplementedError

    def bodies(self, theta, scene, shift=None) -> list:
        """(x, y, angle) of the bodies the layout adds (m, rad), a list of (3,) arrays."""
        return []

    def masses(self, scene) -> list:
        """(m, m, J) of the bodies the layout adds (kg, kg, kg m^2), a list of (3,) arrays."""
        return []

    def body_forces(self, f, bodies, scene):
        """``f`` (nb, 3; N, N m) plus the layout's own forces on its bodies."""
        return f


class FixedCentres(Layout):
    """Every pulley on a fixed bearing."""

    def centers(self, theta, scene, inst, shift=None):
        n = inst.centers.shape[0]
        return (inst.centers if shift is None else inst.centers + shift[:n]), inst.radii

    def tangents(self, centers, radii, scene, inst):
        # the installed tangent points, carried with the (possibly shifted) centres
        nxt = (np.arange(centers.shape[0]) + 1) % centers.shape[0]
        start = centers + (inst.span_start - inst.centers)
        end = centers[nxt] + (inst.span_end - inst.centers[nxt])
        tl = geometry.TangentLine(start, end, inst.span_tangent, inst.span_length)
        return tl, jnp.zeros_like(inst.span_length)


class TensionerArm(Layout):
    """An automatic tensioner: arm angle theta (rad, CCW from +x, pivot to idler), torsion spring
    -k (theta - theta_0) (N m), arm mass and inertia about its centre of mass."""

    coordinates: ClassVar[int] = 1
    body_names: ClassVar[tuple[str, ...]] = ("tensioner arm",)

    def arm_angle(self, rigid, inst):
        return inst.arm_angle + rigid[-1]

    def centers(self, theta, scene, inst, shift=None):
        centers, radii = scene.layout(theta)
        if shift is not None:
            n = centers.shape[0]
            is_idler = jnp.asarray([name == TENSIONER for name in scene.route.order], dtype=centers.dtype)
            centers = centers + is_idler[:, None] * shift[-1] + shift[:n]
        return centers, radii

    def tangents(self, centers, radii, scene, inst):
        senses = jnp.asarray(scene.route.senses, dtype=centers.dtype)
        nxt = (np.arange(len(scene.route.order)) + 1) % len(scene.route.order)
        tl = geometry.tangent_line(centers, radii, senses, centers[nxt], radii[nxt], senses[nxt])
        return tl, _turn(inst.span_tangent, tl.tangent)

    def bodies(self, theta, scene, shift=None) -> list:
        t = scene.tensioner
        cm = t.pivot + t.arm_cm_distance * jnp.stack([jnp.cos(theta), jnp.sin(theta)])
        if shift is not None:
            cm = cm + shift[-1]
        return [jnp.concatenate([cm, theta[None]])]

    def masses(self, scene) -> list:
        t = scene.tensioner
        return [jnp.stack([t.arm_mass, t.arm_mass, t.arm_inertia])]

    def body_forces(self, f, bodies, scene):
        return f.at[-1, 2].add(pivot.elastic_moment(bodies[-1, 2], scene.tensioner))


def spring_moment(theta, scene):
    """Moment of the tensioner spring on the arm (N m): -k (theta - theta_0), theta in rad
    (:func:`beltjax.drive.pivot.spring_moment`)."""
    return pivot.spring_moment(theta, scene.tensioner)


def _turn(a, b):
    """Angle (rad, CCW, in (-pi, pi]) from the 2-vectors a to b, row by row."""
    return jnp.arctan2(geometry._cross(a, b), geometry._dot(a, b))


_FIXED, _ARM = FixedCentres(), TensionerArm()


def layout_of(scene) -> Layout:
    """The layout component of ``scene``: :class:`TensionerArm` with a tensioner, else
    :class:`FixedCentres`."""
    return _FIXED if scene.tensioner is None else _ARM
