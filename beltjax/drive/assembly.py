"""The drive assembled from its scene once: the components and effects it composes and the index
maps every analysis uses (which pulleys turn freely, the drive pulley, coordinate counts, body
and span names).

A :class:`Drive` depends only on the scene's structure (route, which pulleys are driven, the
tensioner's presence, the fidelity and mesh, the listed effects), never on its numbers, so
:func:`drive_of` builds it once per structure and every scene of a sweep or an optimisation
shares it; the physical parameters stay in the scene pytree, where gradients reach them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from beltjax.scene.spec import TENSIONER, drive_pulley_index
from beltjax.drive.effects import Effects, effects_of
from beltjax.drive.layouts import Layout, layout_of
from beltjax.drive.spans import SpanModel, spans_of


@dataclasses.dataclass(frozen=True)
class Drive:
    """A drive's structure: span component, layout component, listed effects, route and index maps.

    spans: :class:`beltjax.drive.spans.SpanModel` (the fidelity); layout:
    :class:`beltjax.drive.layouts.Layout` (fixed centres or a tensioner arm); effects: the
    listed :class:`beltjax.drive.effects.Effects`; route: entry names in route order (the
    tensioner's idler as ``"tensioner"``); senses: wrap senses (+1 CCW, -1 CW); free: per route
    entry, whether its rotation is an independent coordinate; drive_pulley: route index of the
    pulley whose speed sets the belt speed.
    """

    spans: SpanModel
    layout: Layout
    effects: Effects
    route: tuple[str, ...]
    senses: tuple[int, ...]
    free: tuple[bool, ...]
    drive_pulley: int
    rotors: tuple[int, ...] = ()  # route index of each decoupled pulley (its rotor is a body)

    @property
    def span_names(self) -> list[str]:
        """"<from>-<to>" per span in route order (span i leaves route entry i)."""
        n = len(self.route)
        return [f"{self.route[i]}-{self.route[(i + 1) % n]}" for i in range(n)]

    @property
    def body_names(self) -> list[str]:
        """Rigid bodies in the order of the full coordinates: route entries, decoupler rotors,
        then the layout's."""
        return list(self.route) + [f"{self.route[i]} rotor" for i in self.rotors] + list(self.layout.body_names)

    @property
    def n_rigid(self) -> int:
        """Independent rigid-body coordinates: free pulley angles, decoupler rotor angles, then
        the layout's (rad)."""
        return sum(self.free) + len(self.rotors) + self.layout.coordinates

    @property
    def own_bodies(self) -> tuple[int, ...]:
        """The body each own rigid coordinate turns: the free pulleys' angles (route order), then
        the decoupler rotors' (the rigid coordinates before the layout's).  Each moves that body's
        (x, y, angle) only (:func:`beltjax.drive.kinematics.angles_and_arm`, ``rotor_angles``),
        which the rotational model's Jacobian and solve use (:mod:`beltjax.drive.rotational`)."""
        n = len(self.route)
        return tuple(i for i, f in enumerate(self.free) if f) + tuple(n + j for j in range(len(self.rotors)))

    @property
    def n_independent(self) -> int:
        """Independent coordinates: the rigid ones, then the spans'."""
        return self.n_rigid + self.spans.independent * len(self.route)

    @property
    def n_span_coordinates(self) -> int:
        """Span coordinates at the head of the full vector (4 (N+1) per span)."""
        return len(self.route) * 4 * (self.spans.elements + 1)

    @property
    def n_full(self) -> int:
        """Full coordinates: the spans', then (x, y, angle) per body."""
        return self.n_span_coordinates + 3 * len(self.body_names)

    @property
    def travel_follows_drive(self) -> bool:
        """Whether the belt's travel follows the drive pulley's own rotation (it is free)."""
        return self.free[self.drive_pulley]

    @property
    def travel_coordinate(self) -> int:
        """Position in q_i of the drive pulley's angle when it is free."""
        return sum(self.free[: self.drive_pulley])

    @property
    def static_dofs(self) -> np.ndarray:
        """Independent coordinates solved for in statics: all but a free drive pulley's angle
        (a drive whose pulleys are all free turns as a rigid body at no cost; statics holds the
        drive pulley, whose reaction is the drive torque)."""
        dofs = np.arange(self.n_independent)
        return np.delete(dofs, self.travel_coordinate) if self.travel_follows_drive else dofs


def _key(scene) -> tuple:
    m = scene.model
    pulleys = tuple((p.name, bool(p.driven)) for p in scene.pulleys)
    r = scene.route
    return (m.fidelity, m.elements_per_span, m.bending, m.effects, r.order, r.back_side, r.direction, pulleys,
            scene.tensioner is None, tuple(d.pulley for d in scene.decouplers), scene.isolator is None)


#: assembled drives by structure (bounded: cleared when it grows past _CACHE_SIZE)
_CACHE: dict[tuple, Drive] = {}
_CACHE_SIZE = 1024


def _assemble(scene) -> Drive:
    order = scene.route.order
    iso = None if scene.isolator is None else scene.isolator.pulley  # an isolated crank's rim turns freely
    free = tuple(True if name in (TENSIONER, iso) else not scene.pulley(name).driven for name in order)
    name = scene.pulleys[drive_pulley_index(scene.pulleys, order)].name
    return Drive(spans_of(scene), layout_of(scene), effects_of(scene), tuple(order),
                 tuple(int(s) for s in scene.route.senses), free, order.index(name),
                 tuple(order.index(d.pulley) for d in scene.decouplers))


def drive_of(scene) -> Drive:
    """The :class:`Drive` of ``scene``, assembled once per structure (see the module docstring)."""
    key = _key(scene)
    d = _CACHE.get(key)
    if d is None:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.clear()
        d = _CACHE[key] = _assemble(scene)
    return d
