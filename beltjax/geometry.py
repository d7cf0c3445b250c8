"""Drive geometry: pulleys, tangent lines, wrap arcs and the belt path length.

Conventions (those of ``DESIGN.md``):

* units SI: positions and radii in m, angles in rad (counter-clockwise positive
  from the +x axis);
* the belt runs through the pulleys of the route in order, leaving pulley ``i``
  and arriving at pulley ``i + 1`` (the route is cyclic: the last pulley's span
  arrives at the first);
* each pulley has a *wrap sense* ``s`` in {+1, -1}: the belt runs round it
  counter-clockwise (+1) or clockwise (-1).  Pulleys wrapped by the belt's inner
  side turn in the route's ``direction``; pulleys in ``back_side`` are wrapped
  by the belt's back, in the opposite sense (:func:`wrap_senses`);
* the span between two pulleys of the same sense is an *open* tangent, between
  pulleys of opposite senses a *crossed* (internal) tangent.

Everything that produces numbers is pure ``jax.numpy`` without Python branching
on values, so lengths, tangent points and wrap angles are differentiable with
respect to every centre, radius and the tensioner arm angle.  The checks
(:func:`check_drive`) work on concrete numbers and raise a one-line
:class:`GeometryError` (a ``ValueError``) naming the pulleys; they are skipped
when the inputs are traced (inside ``jit``/``grad``).

Derivation of the tangent (used by :func:`tangent_line`).  With ``d = c2 - c1``,
``D = |d|``, unit tangent ``t``, left normal ``m = perp(t)`` and the signed
radius ``r = s1 R1 - s2 R2``: the belt touches pulley ``k`` at
``c_k - s_k R_k m`` (there the travel direction ``s_k perp(n)`` equals ``t``),
so ``d = L t - r m``, whence ``L = sqrt(D^2 - r^2)`` and
``t = (L d/D + r perp(d/D)) / D``.  ``|r| = |R1 - R2|`` for an open tangent and
``R1 + R2`` for a crossed one: the tangent exists iff ``D > |r|``.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from beltjax.errors import BeltjaxError

CW = -1
CCW = +1
DIRECTIONS = ("cw", "ccw")

#: default smallest admissible wrap angle (rad); a smaller one is degenerate
MIN_WRAP = 1e-4


class GeometryError(BeltjaxError):
    """A drive layout that has no belt path (one-line message naming the pulleys).

    Attributes: ``kind`` ("radius", "overlap", "tangent", "wrap", "crossing",
    "through") and ``pulleys``, the route indices of the pulleys involved.
    """

    def __init__(self, message: str = "", key: str = "", *, kind: str = "", pulleys: tuple[int, ...] = ()):
        super().__init__(message, key)
        self.kind = kind
        self.pulleys = tuple(pulleys)


class TangentLine(NamedTuple):
    """A straight span from pulley 1 to pulley 2 (arrays; leading batch dims allowed).

    start: tangent point on pulley 1 (m), shape (..., 2); end: tangent point on
    pulley 2 (m); tangent: unit vector from start to end; length: span length (m).
    """

    start: jax.Array
    end: jax.Array
    tangent: jax.Array
    length: jax.Array


class DriveGeometry(NamedTuple):
    """The belt path of a drive (a pytree of arrays; route order, n pulleys).

    Span ``i`` leaves pulley ``i`` and arrives at pulley ``(i + 1) % n``.

    span_start:    (n, 2) tangent point where span i leaves pulley i (m)
    span_end:      (n, 2) tangent point where span i arrives at pulley i+1 (m)
    span_tangent:  (n, 2) unit vector along span i, in the direction of travel
    span_length:   (n,) length of span i (m)
    arrive_angle:  (n,) polar angle of the arrival point on pulley i (rad, CCW from +x)
    depart_angle:  (n,) polar angle of the departure point on pulley i (rad)
    wrap:          (n,) wrap angle on pulley i (rad, in (0, 2 pi))
    arc_length:    (n,) belt length in contact with pulley i, R_i * wrap_i (m)
    length:        () total belt path length: spans + arcs (m)
    """

    span_start: jax.Array
    span_end: jax.Array
    span_tangent: jax.Array
    span_length: jax.Array
    arrive_angle: jax.Array
    depart_angle: jax.Array
    wrap: jax.Array
    arc_length: jax.Array
    length: jax.Array


# --------------------------------------------------------------------------- helpers


def _perp(v):
    """Rotate 2-vectors by +90 degrees: (x, y) -> (-y, x)."""
    return jnp.stack([-v[..., 1], v[..., 0]], axis=-1)


def _cross(a, b):
    """z-component of the cross product of 2-vectors."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _dot(a, b):
    """Dot product of 2-vectors (last axis), written out: elementwise work that XLA fuses with
    its neighbours (a reduction would end a fused kernel)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _is_traced(*xs) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in xs)


def _names(names, n):
    if names is None:
        return [f"pulley[{i}]" for i in range(n)]
    names = list(names)
    if len(names) != n:
        raise ValueError(f"names: expected {n} names, got {len(names)}")
    return names


# --------------------------------------------------------------------------- senses


def wrap_senses(order: Sequence[str], back_side: Sequence[str] = (), direction: str = "cw") -> np.ndarray:
    """Wrap sense of each pulley of the route: +1 counter-clockwise, -1 clockwise.

    order:     pulley names in the belt's direction of travel
    back_side: names of the pulleys the belt wraps with its back (opposite sense)
    direction: "cw" (default) or "ccw", the sense in which the belt runs round the
               pulleys it wraps with its inner side

    Returns an int array of shape (len(order),) (structural, not a traced value).
    """
    if direction not in DIRECTIONS:
        raise ValueError(f"direction: must be one of {DIRECTIONS}, got {direction!r}")
    unknown = [b for b in back_side if b not in order]
    if unknown:
        raise ValueError(f"back_side: {unknown[0]!r} is not in the route {list(order)}")
    inner = CW if direction == "cw" else CCW
    return np.array([-inner if name in back_side else inner for name in order], dtype=np.int64)


# --------------------------------------------------------------------------- primitives


def tangent_line(c1, r1, s1, c2, r2, s2) -> TangentLine:
    """Tangent span from pulley 1 (the belt leaves it) to pulley 2 (the belt arrives).

    c1, c2: centres (m), shape (..., 2); r1, r2: radii (m); s1, s2: wrap senses
    (+1 CCW, -1 CW).  Equal senses give the open tangent, opposite senses the
    crossed one.  Pure and differentiable; where no tangent exists
    (``D <= |s1 r1 - s2 r2|``) the length is NaN (use :func:`check_drive`).
    Returns a :class:`TangentLine` (points in m, length in m).
    """
    c1 = jnp.asarray(c1)
    c2 = jnp.asarray(c2)
    d = c2 - c1
    D2 = _dot(d, d)
    D = jnp.sqrt(D2)
    sr1 = jnp.asarray(s1) * jnp.asarray(r1)  # signed radii
    sr2 = jnp.asarray(s2) * jnp.asarray(r2)
    r = sr1 - sr2
    L = jnp.sqrt(D2 - r * r)
    e = d / D[..., None]
    t = (L[..., None] * e + r[..., None] * _perp(e)) / D[..., None]
    m = _perp(t)
    start = c1 - sr1[..., None] * m
    end = c2 - sr2[..., None] * m
    return TangentLine(start, end, t, L)


def tensioner_idler_center(pivot, arm_length, theta):
    """Centre of the tensioner idler (m), shape (2,).

    pivot: arm pivot (m), shape (2,); arm_length: pivot-to-idler distance (m);
    theta: arm angle (rad), counter-clockwise from +x, from the pivot to the idler
    centre (the thesis' theta_1).
    """
    pivot = jnp.asarray(pivot)
    return pivot + arm_length * jnp.stack([jnp.cos(theta), jnp.sin(theta)])


def two_pulley_length(D, R1, R2, crossed: bool = False):
    """Closed-form belt length (m) of a two-pulley drive, centre distance D (m).

    open:    2 sqrt(D^2 - (R1-R2)^2) + pi (R1+R2) + 2 (R1-R2) asin((R1-R2)/D)
    crossed: 2 sqrt(D^2 - (R1+R2)^2) + (R1+R2) (pi + 2 asin((R1+R2)/D))
    """
    if crossed:
        S = R1 + R2
        return 2 * jnp.sqrt(D**2 - S**2) + S * (jnp.pi + 2 * jnp.arcsin(S / D))
    d = R1 - R2
    return 2 * jnp.sqrt(D**2 - d**2) + jnp.pi * (R1 + R2) + 2 * d * jnp.arcsin(d / D)


# --------------------------------------------------------------------------- the drive


def _compute(centers, radii, senses) -> DriveGeometry:
    n = centers.shape[0]
    nxt = (np.arange(n) + 1) % n
    s = jnp.asarray(senses, dtype=centers.dtype)
    tl = tangent_line(centers, radii, s, centers[nxt], radii[nxt], s[nxt])
    t_out = tl.tangent  # span i leaves pulley i
    t_in = jnp.roll(tl.tangent, 1, axis=0)  # span i-1 arrives at pulley i
    turn = jnp.arctan2(_cross(t_in, t_out), _dot(t_in, t_out))  # (-pi, pi]
    wrap = jnp.mod(s * turn, 2 * jnp.pi)
    arcs = radii * wrap
    arrive = jnp.roll(tl.end, 1, axis=0) - centers
    depart = tl.start - centers
    return DriveGeometry(
        span_start=tl.start,
        span_end=tl.end,
        span_tangent=tl.tangent,
        span_length=tl.length,
        arrive_angle=jnp.arctan2(arrive[:, 1], arrive[:, 0]),
        depart_angle=jnp.arctan2(depart[:, 1], depart[:, 0]),
        wrap=wrap,
        arc_length=arcs,
        length=jnp.sum(tl.length) + jnp.sum(arcs),
    )


def drive_geometry(
    centers,
    radii,
    senses,
    *,
    names: Sequence[str] | None = None,
    check: bool = True,
    min_wrap: float = MIN_WRAP,
    allow_crossing: bool | None = None,
) -> DriveGeometry:
    """Belt path of a drive: spans, wrap angles, arcs and total length.

    centers: (n, 2) pulley centres in route order (m); radii: (n,) radii (m);
    senses: (n,) wrap senses (+1 CCW, -1 CW; see :func:`wrap_senses`);
    names: pulley names for error messages.

    With ``check=True`` and concrete inputs, :func:`check_drive` runs first and
    raises :class:`GeometryError` on a layout without a belt path; under
    ``jit``/``grad`` the inputs are traced and the checks are skipped.
    Returns a :class:`DriveGeometry` (lengths in m, angles in rad).
    """
    centers = jnp.asarray(centers, dtype=jnp.result_type(float))
    radii = jnp.asarray(radii, dtype=centers.dtype)
    if centers.ndim != 2 or centers.shape[1] != 2 or radii.shape != (centers.shape[0],):
        raise ValueError(f"centers must be (n, 2) and radii (n,), got {centers.shape} and {radii.shape}")
    if centers.shape[0] < 2:
        raise ValueError("a drive needs at least two pulleys in its route")
    if check and not _is_traced(centers, radii):
        check_drive(centers, radii, senses, names=names, min_wrap=min_wrap, allow_crossing=allow_crossing)
    return _compute(centers, radii, senses)


def belt_length(centers, radii, senses):
    """Total belt path length (m): spans plus wrap arcs; pure, no checks.

    centers (n, 2) m, radii (n,) m, senses (n,) +1/-1, in route order.
    """
    centers = jnp.asarray(centers, dtype=jnp.result_type(float))
    return _compute(centers, jnp.asarray(radii, dtype=centers.dtype), senses).length


def _segments_cross(a, b, c, d, tol):
    """Proper intersection of segments ab and cd (numpy, concrete)."""
    def cross(u, v):
        return float(u[0] * v[1] - u[1] * v[0])

    o1 = cross(b - a, c - a)
    o2 = cross(b - a, d - a)
    o3 = cross(d - c, a - c)
    o4 = cross(d - c, b - c)
    return (o1 * o2 < -tol) and (o3 * o4 < -tol)


def _point_segment_distance(p, a, b):
    ab = b - a
    den = float(ab @ ab)
    u = 0.0 if den == 0.0 else min(1.0, max(0.0, float((p - a) @ ab) / den))
    return float(np.linalg.norm(p - (a + u * ab)))


def check_drive(
    centers,
    radii,
    senses,
    *,
    names: Sequence[str] | None = None,
    min_wrap: float = MIN_WRAP,
    allow_crossing: bool | None = None,
) -> None:
    """Raise :class:`GeometryError` (one line, naming the pulleys) if a layout has no belt path.

    Concrete inputs only (centres (n, 2) m, radii (n,) m, senses (n,) +1/-1).
    Checks, in order: radii positive and finite; the tangent from each pulley to
    the next exists (crossed: D > R1 + R2, open: D > |R1 - R2|); no two pulleys
    overlap (centre distance > R1 + R2); every wrap angle lies in
    (min_wrap, 2 pi - min_wrap) rad; no span passes through a pulley other than
    its two ends; and no two spans
    cross each other unless ``allow_crossing`` (None: allowed only for a
    two-pulley route, where opposite senses mean a crossed belt on purpose).
    """
    c = np.asarray(centers, dtype=float)
    R = np.asarray(radii, dtype=float)
    s = np.asarray(senses)
    n = c.shape[0]
    nm = _names(names, n)
    if s.shape != (n,) or not np.all(np.isin(s, (-1, 1))):
        raise ValueError(f"senses: expected {n} values of +1 or -1, got {s.tolist()}")
    if not np.all(np.isfinite(c)):
        i = int(np.argwhere(~np.isfinite(c))[0][0])
        raise GeometryError(f"pulley {nm[i]!r}: centre must be finite, got {c[i].tolist()}", kind="radius", pulleys=(i,))
    for i in range(n):
        if not (np.isfinite(R[i]) and R[i] > 0):
            raise GeometryError(f"pulley {nm[i]!r}: radius must be > 0, got {R[i]!r}", kind="radius", pulleys=(i,))
    scale = max(1.0, float(np.max(np.abs(c))), float(np.max(R)))
    tol = 1e-12 * scale
    for i in range(n):
        j = (i + 1) % n
        D = float(np.linalg.norm(c[j] - c[i]))
        crossed = s[i] != s[j]
        need = R[i] + R[j] if crossed else abs(R[i] - R[j])
        if D <= need + tol:
            kind = "crossed" if crossed else "open"
            rule = "R1 + R2" if crossed else "|R1 - R2|"
            raise GeometryError(
                f"no {kind} tangent from {nm[i]!r} to {nm[j]!r}: centre distance {D:.6g} m "
                f"<= {rule} = {need:.6g} m",
                kind="tangent",
                pulleys=(i, j),
            )
    for i in range(n):
        for j in range(i + 1, n):
            D = float(np.linalg.norm(c[j] - c[i]))
            if D <= R[i] + R[j] + tol:
                raise GeometryError(
                    f"pulleys {nm[i]!r} and {nm[j]!r} overlap: centre distance {D:.6g} m "
                    f"<= R1 + R2 = {R[i] + R[j]:.6g} m",
                    kind="overlap",
                    pulleys=(i, j),
                )
    g = _compute(jnp.asarray(c), jnp.asarray(R), s)
    wrap = np.asarray(g.wrap)
    for i in range(n):
        if not (min_wrap < wrap[i] < 2 * math.pi - min_wrap):
            raise GeometryError(
                f"wrap angle on pulley {nm[i]!r} degenerates: {math.degrees(wrap[i]) + 0.0:.6g} deg "
                f"(the belt only grazes it, or would loop round it)",
                kind="wrap",
                pulleys=(i,),
            )
    start = np.asarray(g.span_start)
    end = np.asarray(g.span_end)

    def span_name(i):
        return f"{nm[i]!r} -> {nm[(i + 1) % n]!r}"

    for i in range(n):
        for k in range(n):
            if k in (i, (i + 1) % n):
                continue
            if _point_segment_distance(c[k], start[i], end[i]) < R[k] - tol:
                raise GeometryError(
                    f"span {span_name(i)} passes through pulley {nm[k]!r}", kind="through", pulleys=(i, (i + 1) % n, k)
                )
    if allow_crossing is None:
        allow_crossing = n == 2
    if not allow_crossing:
        for i in range(n):
            for j in range(i + 1, n):
                if _segments_cross(start[i], end[i], start[j], end[j], tol * tol):
                    raise GeometryError(
                        f"spans {span_name(i)} and {span_name(j)} cross each other "
                        f"(check route.order and back_side)",
                        kind="crossing",
                        pulleys=(i, (i + 1) % n, j, (j + 1) % n),
                    )
