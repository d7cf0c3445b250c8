"""The hybrid drive model (thesis ch. 4): one kinematic map, reduced mass and forces.

Bodies and spans
----------------
Every route entry is a rigid pulley (the tensioner's idler included) with full
coordinates ``(x, y, angle)`` of its centre; a tensioner adds its arm as one more
rigid body ``(x_cm, y_cm, theta)``.  Each span between consecutive route entries
is a chain of ``N`` ANCF elements (``N + 1`` nodes of ``(x, y, x', y')``, global
frame).  The full coordinate vector ``q`` stacks the spans, then the bodies.

Independent coordinates ``q_i``
-------------------------------
* the rotation perturbation ``phi`` (rad, CCW) of every pulley that is not
  driven (a driven pulley's motion is prescribed: zero in statics and modal);
* the tensioner arm's angle change ``dtheta`` (rad) from the installation angle;
* per span, the two end slopes and all coordinates of its interior nodes (4 N).

The kinematic map ``q = Phi(q_i)`` (:func:`full_coordinates`) holds every
constraint of the drive (eqs. 4.37-4.46, 4.99-4.113 of the thesis): pulley centres
fixed or carried by the arm, and span end nodes pinned at their tangent points.
A span end node sits at its installation tangent point, is carried rigidly with
its pulley's centre (the arm for the idler) and slides along the span by
``s R phi`` when its pulley turns by ``phi`` (``s`` the wrap sense).  ``phi`` is
only the perturbation: the belt's steady motion is the transport speed ``c`` of
the Eulerian (ALE) span elements, so a steadily turning pulley does not drag
the span nodes away from the tangent points.

Reduced equations: ``M_ii = J^T M J`` and ``F_ii = J^T (F - M gamma)`` with the
Jacobian ``J = dPhi/dq_i`` (autodiff; it is the junction structure of the
power-port picture) and ``gamma = dJ/dt q_i_dot``.  ``F`` holds only the effects
the scene lists (``[model] effects``): elastic forces always, ``transport``
(gyroscopic + centrifugal terms of the moving belt) and ``gravity`` when asked
for; an effect not listed is not traced into the compiled function.
The rotational model's spans are massless bars, so the same equations need only the bodies'
rows of ``J`` and the span lengths ``l(q_i)`` (:func:`span_lengths`, closed form):
:func:`reduced_accelerations` takes that road for it (tests/test_fast_paths.py checks it
against the dense ``J^T M J`` solve with every effect).

Units: SI throughout (m, rad, N, N m, kg, kg m^2, s).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, geometry, span
from beltjax.ancf import Section
from beltjax.scene import ARM, TENSIONER, Scene

GRAVITY = (0.0, -9.81)  # m/s^2


# --------------------------------------------------------------------------- structure


class Installation(NamedTuple):
    """The belt as installed (a pytree of arrays; see :func:`beltjax.statics.install`).

    arm_angle: tensioner arm angle theta_1 (rad; 0 without a tensioner);
    stretch: uniform stretch lam of the belt at installation (-);
    tension: installation tension (N); belt_length: unstretched belt length (m);
    centers (n, 2) m and radii (n,) m in route order; span_start, span_end (n, 2):
    tangent points (m); span_tangent (n, 2): unit vectors; span_length (n,) m:
    installed span lengths; wrap (n,) rad.
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


def canonical(scene: Scene) -> Scene:
    """The scene without its file label and description, so that scenes differing only in
    numbers share one compiled function."""
    return dataclasses.replace(scene, source="", description="")


def span_names(scene: Scene) -> list[str]:
    """Names of the spans in route order: "<from>-<to>" (span i leaves route entry i)."""
    return scene.route.span_names


def is_free(scene: Scene) -> list[bool]:
    """Per route entry: whether its rotation is an independent coordinate (not driven)."""
    return [True if name == TENSIONER else not scene.pulley(name).driven for name in scene.route.order]


def flexible(scene: Scene) -> bool:
    """True for the hybrid ANCF fidelity; False for the rotational (Newton-Euler) one, whose
    spans are massless axial springs between their end nodes."""
    return scene.model.fidelity == "ancf"


def span_elements(scene: Scene) -> int:
    """Elements per span in the full coordinates: the mesh (ancf) or 1 (rotational: a bar)."""
    return scene.model.elements_per_span if flexible(scene) else 1


def n_rigid(scene: Scene) -> int:
    """Number of independent rigid-body coordinates (free pulley angles, arm angle)."""
    return sum(is_free(scene)) + (1 if scene.tensioner is not None else 0)


def n_independent(scene: Scene) -> int:
    """Number of independent coordinates of the drive."""
    per_span = 4 * scene.model.elements_per_span if flexible(scene) else 0
    return n_rigid(scene) + per_span * len(scene.route.order)


def n_span_coordinates(scene: Scene) -> int:
    """Number of span coordinates at the head of the full vector (4 (N+1) per span)."""
    return len(scene.route.order) * 4 * (span_elements(scene) + 1)


def n_full(scene: Scene) -> int:
    """Number of full coordinates (spans, then 3 per body)."""
    n = len(scene.route.order)
    return n_span_coordinates(scene) + 3 * (n + (1 if scene.tensioner is not None else 0))


def body_names(scene: Scene) -> list[str]:
    """Rigid bodies in the order of the full coordinates: route entries, then "tensioner arm"."""
    names = list(scene.route.order)
    if scene.tensioner is not None:
        names.append("tensioner arm")
    return names


def static_dofs(scene: Scene) -> np.ndarray:
    """Independent coordinates solved for in statics: all but a free drive pulley's angle.

    A drive whose pulleys are all free turns as a rigid body at no cost (zero
    stiffness); statics holds the drive pulley (its reaction is the drive torque).
    """
    k = drive_pulley(scene)
    free = is_free(scene)
    dofs = np.arange(n_independent(scene))
    if free[k]:
        return np.delete(dofs, sum(free[:k]))
    return dofs


def travel_follows_drive(scene: Scene) -> bool:
    """Whether a transient's belt travel follows the drive pulley's own rotation: when that
    pulley is free (no pulley of the route is driven, e.g. a crank turned by a [[torque]]).

    The belt then travels x = x_b(t) + s R phi_d (m: the nominal travel of
    :func:`belt_travel` plus the drive pulley's rim travel beyond it), its transport speed is
    c = s R theta_d' / lam, and every span end slides by its pulley's rim travel less x
    (:func:`full_coordinates`); otherwise x = x_b(t) is prescribed.
    """
    return is_free(scene)[drive_pulley(scene)]


def travel_coordinate(scene: Scene) -> int:
    """Position in q_i of the drive pulley's angle when it is free (:func:`travel_follows_drive`)."""
    d = drive_pulley(scene)
    return sum(is_free(scene)[:d])


def drive_pulley(scene: Scene) -> int:
    """Route index of the pulley whose speed sets the belt speed.

    The driven pulley (the first one in the file if several), else the first
    pulley of the file.
    """
    order = scene.route.order
    driven = [p.name for p in scene.pulleys if p.driven and p.name in order]
    name = driven[0] if driven else next(p.name for p in scene.pulleys if p.name in order)
    return order.index(name)


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


# --------------------------------------------------------------------------- kinematic map


def _split(qi, scene: Scene):
    nr = n_rigid(scene)
    n = len(scene.route.order)
    if not flexible(scene):
        return qi[:nr], None
    N = scene.model.elements_per_span
    return qi[:nr], qi[nr:].reshape(n, 4 * N)


def angles_and_arm(qi, scene: Scene, inst: Installation, driven_angle=0.0):
    """Pulley rotation perturbations (n,) rad in route order, and the arm angle (rad).

    driven_angle: rotation perturbation of the driven pulleys (rad), a scalar or (n,) in
    route order (entries of free pulleys ignored).
    """
    rigid, _ = _split(qi, scene)
    free = is_free(scene)
    driven = jnp.broadcast_to(jnp.asarray(driven_angle, dtype=qi.dtype), (len(free),))
    k, phis = 0, []
    for i, f in enumerate(free):
        if f:
            phis.append(rigid[k])
            k += 1
        else:
            phis.append(driven[i])
    theta = inst.arm_angle + (rigid[-1] if scene.tensioner is not None else 0.0)
    return jnp.stack(phis), theta


def belt_travel(scene: Scene, t):
    """Nominal belt travel x_b(t) (m) along the route, set by the drive pulley's prescribed
    motion: speed |speed_rpm|, run-up at acceleration_rpm_per_s up to target_speed_rpm, and
    (``speed_fluctuation``) the harmonic fluctuation R A sin(2 pi f t) of its angle.

    Every pulley rolls with it (angle s_i x_b / R_i) and the belt's transport speed is its
    rate, so the fluctuation reaches the centrifugal and rhoA dc/dt terms as in the thesis
    (c = R theta').  Its first and second time derivatives (m/s, m/s^2) come by autodiff.
    """
    p = scene.pulley(scene.route.order[drive_pulley(scene)])
    rpm = 2 * jnp.pi / 60.0
    w0 = jnp.abs(p.speed_rpm) * rpm
    a = p.acceleration_rpm_per_s * rpm
    if p.target_speed_rpm is None:
        angle = w0 * t + 0.5 * a * t**2
    else:
        wT = p.target_speed_rpm * rpm
        t_star = (wT - w0) / jnp.where(a == 0.0, 1.0, a)
        tau = jnp.minimum(t, t_star)
        angle = w0 * tau + 0.5 * a * tau**2 + wT * (t - tau)
    if scene.model.has("speed_fluctuation"):
        A = jnp.deg2rad(p.fluctuation_amplitude_deg)
        angle = angle + A * jnp.sin(2 * jnp.pi * p.fluctuation_frequency_hz * t)
    return p.radius * angle


def n_reaction_points(scene: Scene) -> int:
    """Bearings whose reactions are reported: one per route entry, plus the arm pivot."""
    return len(scene.route.order) + (1 if scene.tensioner is not None else 0)


def full_coordinates(qi, scene: Scene, inst: Installation, driven_angle=0.0, t=None, shift=None):
    """The kinematic map q = Phi(q_i, t): full coordinates from independent ones.

    qi: independent coordinates (m, rad, -); driven_angle: prescribed rotation
    perturbation of driven pulleys (rad, scalar or (n,) route order); t: time (s), for
    transients: each pulley then also turns by its nominal rolling angle
    s_i x_b(t) / R_i (:func:`belt_travel`, speed fluctuation included), and when the drive
    pulley is free the belt travels with it (:func:`travel_follows_drive`): every span end
    slides by its pulley's rim travel less the drive pulley's, s R phi - s_d R_d phi_d, so a
    free crank may turn any amount; None (statics, modes) leaves both out (there the drive
    pulley is held, or its rotation is the rigid turn of the loop).  shift: virtual displacement (m) of every
    bearing, shape (n_reaction_points, 2) (route entries, then the arm pivot), used to
    compute bearing reactions; None = 0.  Returns the full vector: span coordinates
    (n spans x 4 (N+1)), then (x, y, angle) per body (m, rad); with ``unbalance`` the
    (x, y) of a pulley is the centre of mass of the pulley (offset by cm_offset, turning
    with it) and of its wrapped belt (on the axis).
    """
    N = span_elements(scene)
    _, spans = _split(qi, scene)
    phi, theta = angles_and_arm(qi, scene, inst, driven_angle)
    centers, radii = _centers(theta, scene, inst, shift)
    travel = 0.0
    if t is not None and travel_follows_drive(scene):  # the belt travels with the free drive pulley
        d = drive_pulley(scene)
        travel = scene.route.senses[d] * radii[d] * phi[d]
    start, end, t_hat = _span_ends(phi, centers, radii, scene, inst, travel)
    parts = []
    for s in range(len(scene.route.order)):
        if spans is None:  # rotational: a bar between the end nodes; slopes are not used
            slope = inst.stretch * t_hat[s]
            nodes = jnp.concatenate([start[s], slope, end[s], slope])
            parts.append(nodes)
            continue
        body = spans[s]
        nodes = jnp.concatenate([start[s], body[:2], body[2:-2], end[s], body[-2:]])
        parts.append(nodes)
        assert nodes.shape[0] == 4 * (N + 1)
    return jnp.concatenate(parts + [_body_coordinates(phi, theta, centers, scene, inst, t, shift)])


def _centers(theta, scene: Scene, inst: Installation, shift=None):
    """Pulley centres (n, 2) m and radii (n,) m in route order at arm angle theta (rad),
    bearings shifted by ``shift`` (see :func:`full_coordinates`)."""
    n = len(scene.route.order)
    if scene.tensioner is not None:
        centers, radii = scene.layout(theta)
        if shift is not None:
            is_idler = jnp.asarray([name == TENSIONER for name in scene.route.order], dtype=centers.dtype)
            centers = centers + is_idler[:, None] * shift[-1]
    else:
        centers, radii = inst.centers, inst.radii
    if shift is not None:
        centers = centers + shift[:n]
    return centers, radii


def _span_ends(phi, centers, radii, scene: Scene, inst: Installation, travel=0.0):
    """Span end nodes (start, end, each (n, 2) m) and span directions (n, 2) of the kinematic
    map, for pulley rotation perturbations phi (n,) rad, centres (n, 2) m and radii (n,) m
    (:func:`_centers`); travel: the belt's travel beyond the nominal one (m), taken off every
    pulley's rim slide (the end nodes sit on the belt's Eulerian mesh, which moves with it).
    end - start is along the direction: the span's length is (end - start) . t_hat."""
    n = len(scene.route.order)
    senses = jnp.asarray(scene.route.senses, dtype=centers.dtype)
    nxt = (np.arange(n) + 1) % n
    if scene.tensioner is None:
        # fixed centres: the installed tangent points, each end node slid along its span by the
        # rim travel of its pulley (belt fed into or drawn out of the span)
        slide = senses * radii * phi - travel  # rim travel of each pulley along the belt (m)
        t_hat = inst.span_tangent
        start = centers + (inst.span_start - inst.centers) + slide[:, None] * t_hat
        end = centers[nxt] + (inst.span_end - inst.centers[nxt]) + slide[nxt][:, None] * t_hat
        return start, end, t_hat
    # the idler moves with the arm: the exact tangent points of the moved layout, and the belt
    # on each arc, which turns with its pulley, gains s R dpsi where its end point moved by dpsi
    # (rad, CCW) from the installed one; the end node slides by the rim travel less that
    # (s R (phi - dpsi)).  Spans and arcs then keep the belt's length exactly as the arm swings
    # (moving the tangent points rigidly with the centres was exact to first order only).
    tl, dpsi = _moved_tangents(centers, radii, scene, inst)
    t_hat = tl.tangent
    start = tl.start + (senses * radii * (phi - dpsi) - travel)[:, None] * t_hat
    end = tl.end + (senses[nxt] * radii[nxt] * (phi[nxt] - dpsi) - travel)[:, None] * t_hat
    return start, end, t_hat


def _body_coordinates(phi, theta, centers, scene: Scene, inst: Installation, t=None, shift=None):
    """(x, y, angle) of every body, flattened (m, rad): pulleys in route order, then the arm
    (see :func:`full_coordinates`)."""
    order = scene.route.order
    senses = jnp.asarray(scene.route.senses, dtype=centers.dtype)
    angle = phi if t is None else phi + senses * belt_travel(scene, t) / inst.radii
    unbalance = scene.model.has("unbalance")
    bodies = []
    if unbalance:  # the body (x, y) is the centre of mass of pulley + wrapped belt
        m_arc = scene.belt.rhoA * inst.radii * inst.wrap / inst.stretch
    for i in range(len(order)):
        pos = centers[i]
        if unbalance and order[i] != TENSIONER:
            p = scene.pulley(order[i])
            e = p.cm_offset * p.mass / (p.mass + m_arc[i])
            c, sn = jnp.cos(angle[i]), jnp.sin(angle[i])
            pos = pos + jnp.stack([c * e[0] - sn * e[1], sn * e[0] + c * e[1]])
        bodies.append(jnp.concatenate([pos, angle[i][None]]))
    if scene.tensioner is not None:
        tt = scene.tensioner
        cm = tt.pivot + tt.arm_cm_distance * jnp.stack([jnp.cos(theta), jnp.sin(theta)])
        if shift is not None:
            cm = cm + shift[-1]
        bodies.append(jnp.concatenate([cm, theta[None]]))
    return jnp.concatenate(bodies)


def _moved_tangents(centers, radii, scene: Scene, inst: Installation):
    """Tangent lines of the layout with these centres (m) and radii (m), and how far each span's
    direction turned from the installed one, dpsi (n,) rad CCW.  Both tangent points of a span
    lie on the normal to its direction, so each turned by dpsi on its pulley."""
    senses = jnp.asarray(scene.route.senses, dtype=centers.dtype)
    nxt = (np.arange(len(scene.route.order)) + 1) % len(scene.route.order)
    tl = geometry.tangent_line(centers, radii, senses, centers[nxt], radii[nxt], senses[nxt])
    return tl, _turn(inst.span_tangent, tl.tangent)


def span_lengths(qi, scene: Scene, inst: Installation):
    """Stretched span lengths (m), shape (n,): the distance between each span's end nodes in
    the kinematic map (:func:`full_coordinates`).  The rotational model's spans are bars of
    these lengths.

    In closed form: l = L + r dpsi + s' R' phi' - s R phi, with L the tangent length of the
    (moved) layout, r = s R - s' R' the signed radius difference of the span's pulleys (from
    ``s R`` to ``s' R'``) and dpsi (rad) how far the span's direction turned from the installed
    one (:func:`_moved_tangents`): the end slides of :func:`_span_ends` are s R (phi - dpsi) and
    s' R' (phi' - dpsi).
    """
    phi, theta = angles_and_arm(qi, scene, inst)
    centers, radii = _centers(theta, scene, inst)
    slides = _rim_slides(phi, radii, scene)
    if scene.tensioner is None:
        return inst.span_length + slides
    sr = jnp.asarray(scene.route.senses, dtype=qi.dtype) * radii
    nxt = (np.arange(len(scene.route.order)) + 1) % len(scene.route.order)
    tl, dpsi = _moved_tangents(centers, radii, scene, inst)
    return tl.length + (sr - sr[nxt]) * dpsi + slides


def _rim_slides(phi, radii, scene: Scene):
    """s' R' phi' - s R phi (m) per span: how much the pulley rotations phi (n,) rad lengthen
    each span (radii (n,) m, route order)."""
    sr = jnp.asarray(scene.route.senses, dtype=phi.dtype) * radii
    nxt = (np.arange(len(scene.route.order)) + 1) % len(scene.route.order)
    return sr[nxt] * phi[nxt] - sr * phi


def span_lengths_and_jacobian(qi, scene: Scene, inst: Installation):
    """:func:`span_lengths` (n,) m and their Jacobian dl/dq_i (n, n_i) (m/rad) of the rotational
    model.

    The rim slides are linear in the pulley angles and the layout moves with the arm angle
    only, so the Jacobian is the slides' (constant in q_i) plus one column, the derivative along
    the arm angle: one forward pass (jvp) instead of one per coordinate (jacfwd), which
    matters in a vector field evaluated tens of thousands of times per simulated second.
    """
    if scene.tensioner is None:  # fixed centres: linear in q_i
        return span_lengths(qi, scene, inst), jax.jacfwd(span_lengths)(qi, scene, inst)
    e_arm = jnp.zeros_like(qi).at[n_rigid(scene) - 1].set(1.0)  # the arm angle, last rigid coordinate
    l, dl_arm = jax.jvp(lambda x: span_lengths(x, scene, inst), (qi,), (e_arm,))

    def slides(x):
        phi, theta = angles_and_arm(x, scene, inst)
        return _rim_slides(phi, _centers(theta, scene, inst)[1], scene)

    return l, jax.jacfwd(slides)(qi) + dl_arm[:, None] * e_arm[None, :]


def _turn(a, b):
    """Angle (rad, CCW, in (-pi, pi]) from the 2-vectors a to b, row by row."""
    return jnp.arctan2(geometry._cross(a, b), geometry._dot(a, b))


def split_full(q, scene: Scene):
    """Full vector -> (spans (n, 4 (N+1)), bodies (nb, 3))."""
    ns = n_span_coordinates(scene)
    return q[:ns].reshape(len(scene.route.order), -1), q[ns:].reshape(-1, 3)


def installed_coordinates(scene: Scene, inst: Installation):
    """Independent coordinates of the installed drive: straight spans at the installation stretch."""
    if not flexible(scene):
        return jnp.zeros(n_rigid(scene))
    n = len(scene.route.order)
    N = scene.model.elements_per_span
    x = jnp.linspace(0.0, 1.0, N + 1)
    pos = inst.span_start[:, None, :] + x[None, :, None] * (inst.span_end - inst.span_start)[:, None, :]
    slope = jnp.broadcast_to((inst.stretch * inst.span_tangent)[:, None, :], (n, N + 1, 2))
    nodes = jnp.concatenate([pos, slope], axis=-1).reshape(n, 4 * (N + 1))
    spans = jnp.concatenate([nodes[:, 2 : 4 * N], nodes[:, 4 * N + 2 :]], axis=1)  # drop end positions
    return jnp.concatenate([jnp.zeros(n_rigid(scene)), spans.reshape(-1)])


# --------------------------------------------------------------------------- full mass and forces


def body_masses(scene: Scene, inst: Installation | None = None):
    """Diagonal of the bodies' mass matrix: (m, m, J) per body (kg, kg, kg m^2).

    With ``inst``, each pulley also carries the belt wrapped round it (no slip):
    mass rhoA R wrap / lam and inertia that times R^2 (the arc's centre of mass is
    taken at the pulley centre).
    """
    vals = []
    for name in scene.route.order:
        if name == TENSIONER:
            t = scene.tensioner
            vals.append(jnp.stack([t.pulley_mass, t.pulley_mass, t.pulley_inertia]))
        else:
            p = scene.pulley(name)
            vals.append(jnp.stack([p.mass, p.mass, p.inertia]))
    if inst is not None:
        m_arc = scene.belt.rhoA * inst.radii * inst.wrap / inst.stretch
        vals = [v + jnp.stack([m, m, m * R**2]) for v, m, R in zip(vals, m_arc, inst.radii)]
    if scene.tensioner is not None:
        t = scene.tensioner
        vals.append(jnp.stack([t.arm_mass, t.arm_mass, t.arm_inertia]))
    return jnp.concatenate(vals)


def full_mass_matrix(scene: Scene, inst: Installation):
    """Block-diagonal mass matrix of the full coordinates (kg, kg m^2)."""
    n = len(scene.route.order)
    N = span_elements(scene)
    idx = span.element_index(N)
    Le = element_length(scene, inst)
    if flexible(scene):
        blocks = [span.span_mass_matrix(scene.belt.rhoA, Le[s], idx) for s in range(n)]
    else:  # massless springs (the thesis' rotational model)
        blocks = [jnp.zeros((4 * (N + 1), 4 * (N + 1))) for _ in range(n)]
    blocks.append(jnp.diag(body_masses(scene, inst)))
    return jax.scipy.linalg.block_diag(*blocks)


def _span_potential(e, sec: Section, Le, idx, bending, gravity: bool):
    U = span.span_strain_energy(e, sec, Le, idx, bending)
    if gravity:
        U = U + jnp.sum(jax.vmap(ancf.gravity_energy, in_axes=(0, None, None, None))(e[idx], sec.rhoA, Le, GRAVITY))
    return U


def span_forces(e, e_dot, s: int, scene: Scene, inst: Installation, c=0.0, c_dot=0.0, dissipative=False):
    """Forces on the coordinates of span ``s`` (N): elastic, plus the listed effects.

    e, e_dot: the span's coordinates and rates; c: transport speed (m/s of
    unstretched belt), c_dot its rate (m/s^2).  ``transport`` adds the
    gyroscopic, centrifugal and rhoA dc/dt terms, ``gravity`` the weight;
    with ``dissipative`` (transients) ``belt_damping`` adds the viscous axial
    force of CA (N s): Rayleigh function 1/2 int CA (d eps/dt)^2 dx.
    """
    damp = dissipative and scene.model.has("belt_damping")
    if not flexible(scene):
        return _bar_forces(e, e_dot if damp else None, s, scene, inst, c)
    N = scene.model.elements_per_span
    idx = span.element_index(N)
    sec = section(scene)
    Le = element_length(scene, inst)[s]
    grav = scene.model.has("gravity")
    f = -jax.grad(_span_potential)(e, sec, Le, idx, scene.model.bending, grav)
    if scene.model.has("transport"):
        f = f + span.span_inertial_forces(e, e_dot, c, c_dot, sec.rhoA, Le, idx)
    if damp:
        f = f - jax.grad(_span_dissipation, argnums=1)(e, e_dot, scene.belt.CA, Le, idx)
    return f


def _element_dissipation(e, e_dot, CA, L):
    """Rayleigh function of an element (W): 1/2 int CA (r'.r'_t)^2 dx (Green-Lagrange strain rate)."""

    def density(xi):
        return 0.5 * CA * (ancf.slope(e, xi, L) @ ancf.slope(e_dot, xi, L)) ** 2

    return L * jnp.sum(ancf.WEIGHTS * jax.vmap(density)(ancf.XI))


def _span_dissipation(e, e_dot, CA, Le, idx):
    return jnp.sum(jax.vmap(_element_dissipation, in_axes=(0, 0, None, None))(e[idx], e_dot[idx], CA, Le))


def _bar_energy(e, L0, EA, rhoA, c):
    """Axial energy of a straight span as one bar, minus its transport (centrifugal) term (J).

    Green-Lagrange, as the ANCF element: 1/2 EA L0 ((l/L0)^2 - 1)^2 / 4, so the axial force
    is EA (lam^2 - 1)/2 * lam with lam = l / L0; the moving belt's kinetic energy
    1/2 rhoA c^2 l^2 / L0 acts as a negative potential (hub force reduced by rhoA v^2).
    """
    d = e[4:6] - e[0:2]
    return _bar_energy_l2(d @ d, L0, EA, rhoA, c)


def _bar_energy_l2(l2, L0, EA, rhoA, c):
    """:func:`_bar_energy` of a bar of squared length l2 (m^2)."""
    eps = 0.5 * (l2 / L0**2 - 1.0)
    return 0.5 * EA * L0 * eps**2 - 0.5 * rhoA * c**2 * l2 / L0


def _bar_forces(e, e_dot, s: int, scene: Scene, inst: Installation, c=0.0):
    """Forces of a span of the rotational model on its end nodes (N), shape (8,).

    e_dot: node rates for the viscous force (CA / L0) dl/dt along the bar (thesis eq. 4.15),
    or None (no damping).
    """
    L0 = element_length(scene, inst)[s]
    cc = c if scene.model.has("transport") else 0.0
    f = -jax.grad(_bar_energy)(e, L0, scene.belt.EA, scene.belt.rhoA, cc)
    if e_dot is not None:
        d = e[4:6] - e[0:2]
        u = d / jnp.linalg.norm(d)
        rate = u @ (e_dot[4:6] - e_dot[0:2])
        fd = scene.belt.CA / L0 * rate * u
        f = f.at[0:2].add(fd).at[4:6].add(-fd)
    return f


def body_forces(bodies, scene: Scene, inst: Installation | None = None, bodies_dot=None, t=None):
    """Applied forces on the bodies (nb, 3): spring moment on the arm, weights (N, N m).

    With a time ``t`` (s; transients) and the bodies' rates ``bodies_dot``: the listed
    damping effects (bearing: -c_b times the pulley's absolute speed; tensioner: -c
    times the arm's speed, N m s/rad) and the [[torque]] loads (N m).
    """
    f = jnp.zeros_like(bodies)
    if scene.tensioner is not None:
        f = f.at[-1, 2].add(spring_moment(bodies[-1, 2], scene))
    if scene.model.has("gravity"):
        f = f.at[:, 1].add(GRAVITY[1] * body_masses(scene, inst).reshape(-1, 3)[:, 0])
        if inst is not None and flexible(scene):
            f = f.at[: len(scene.route.order), 2].add(_belt_weight_slide_moments(scene, inst, t is not None))
    if t is None:
        return f
    order = scene.route.order
    if scene.model.has("bearing_damping"):
        for i, name in enumerate(order):
            if name != TENSIONER:
                f = f.at[i, 2].add(-scene.pulley(name).bearing_damping * bodies_dot[i, 2])
    if scene.tensioner is not None and scene.model.has("tensioner_damping"):
        f = f.at[-1, 2].add(-scene.tensioner.damping * bodies_dot[-1, 2])
    for load in scene.torques:
        k = -1 if load.pulley == ARM else order.index(load.pulley)
        f = f.at[k, 2].add(torque(load, t))
    return f


def _belt_weight_slide_moments(scene: Scene, inst: Installation, transient: bool = False):
    """Moments (N m) on the pulleys that make a rigid turn of the belt loop cost no weight.

    A pulley's rotation perturbation slides the span end nodes along their spans (s R phi);
    the belt itself flows through the spans, so sliding a span along its own line must not
    move its weight.  The span's weight is counted with its nodes shifted back by the
    interpolated end slides, (1 - x) s0 + x s1 along the span: that adds the potential
    rhoA (g . t) L0 (s0 + s1) / 2 per span, i.e. these constant moments (a pure moment: the
    bearing forces are unchanged).  In a transient whose belt travels with a free drive
    pulley (:func:`travel_follows_drive`) the slides are taken relative to that travel,
    s R phi - s_d R_d phi_d, which adds to the drive pulley's moment minus s_d R_d times the
    others' sum of m_i / (s_i R_i): a rigid turn of the loop, which then moves no node, does no
    work either.
    """
    n = len(scene.route.order)
    g = jnp.asarray(GRAVITY)
    L0 = element_length(scene, inst) * scene.model.elements_per_span
    senses = jnp.asarray(scene.route.senses, dtype=L0.dtype)
    w = scene.belt.rhoA * (inst.span_tangent @ g) * L0 / 2  # per span, N
    prev = (np.arange(n) - 1) % n
    m = -(w + w[prev]) * senses * inst.radii
    if transient and travel_follows_drive(scene):
        d = drive_pulley(scene)
        m = m.at[d].add(-senses[d] * inst.radii[d] * jnp.sum(m / (senses * inst.radii)))
    return m


def _window(t, t_start, t_end):
    on = t >= t_start
    if t_end is not None:
        on = on & (t < t_end)
    return jnp.where(on, 1.0, 0.0)


def torque(load, t):
    """Moment of a [[torque]] load at time t (N m, CCW positive)."""
    w = 2 * jnp.pi * load.frequency_hz * t + jnp.deg2rad(load.phase_deg)
    return _window(t, load.t_start_s, load.t_end_s) * (load.mean_Nm + load.amplitude_Nm * jnp.sin(w))


def span_load_force(load, t):
    """Magnitude of a [[span_load]] force at time t (N), normal to the installed span."""
    w = 2 * jnp.pi * load.frequency_hz * t + jnp.deg2rad(load.phase_deg)
    return _window(t, load.t_start_s, load.t_end_s) * load.amplitude_N * jnp.sin(w)


def spring_moment(theta, scene: Scene):
    """Moment of the tensioner spring on the arm (N m): -k (theta - theta_0)."""
    t = scene.tensioner
    return -t.spring_stiffness * (theta - jnp.deg2rad(t.spring_preload_deg))


def full_forces(q, q_dot, scene: Scene, inst: Installation, c=0.0, c_dot=0.0, t=None):
    """Forces on all full coordinates (N, N m) for the listed effects.

    t: time (s) for transients: adds the dissipative effects and the loads; None gives the
    conservative steady forces of statics and modal analysis.
    """
    E, B = split_full(q, scene)
    Ed, Bd = split_full(q_dot, scene)
    dyn = t is not None
    fs = [span_forces(E[s], Ed[s], s, scene, inst, c, c_dot, dissipative=dyn) for s in range(E.shape[0])]
    if dyn and scene.span_loads:
        names = span_names(scene)
        for load in scene.span_loads:
            s = names.index(load.span)
            tan = inst.span_tangent[s]
            normal = jnp.stack([-tan[1], tan[0]])
            fs[s] = fs[s].at[4 * load.node : 4 * load.node + 2].add(span_load_force(load, t) * normal)
    return jnp.concatenate(fs + [body_forces(B, scene, inst, Bd, t).reshape(-1)])


# --------------------------------------------------------------------------- reduced equations


def transport_speed(scene: Scene, inst: Installation, speed):
    """Transport speed c (m of unstretched belt per s) for a belt speed ``speed`` (m/s)."""
    return speed / inst.stretch


def full_motion(qi, qi_dot, scene: Scene, inst: Installation, speed=0.0, t=None, rigid_only=False):
    """Full coordinates and what the reduced equations need of them, at (q_i, q_i', t).

    Returns (q, v, gamma, J, F): q = Phi(q_i, t) and its rate v; gamma = d(J q_i')/dt at
    q_i'' = 0 (with the time terms of Phi); J = dPhi/dq_i; the forces F of
    :func:`full_forces`.  speed: belt speed (m/s) when ``t`` is None (steady motion, the
    map without time); with a time t (s) the belt speed and its rate follow
    :func:`belt_travel` and the damping effects and loads act.  rigid_only: J holds only
    the columns of the rigid coordinates, ``J[:, :n_rigid]`` (the span columns are the
    constant selection of :func:`span_coordinate_index`).
    """
    if rigid_only:
        nr = n_rigid(scene)
        q, v, gamma, _, F = _full_motion(qi, qi_dot, scene, inst, speed, t, skip_jacobian=True)
        steady = t is None
        tt = jnp.zeros((), dtype=qi.dtype) if steady else jnp.asarray(t, dtype=qi.dtype)
        rest = qi[nr:]

        def phi_r(xr):
            return full_coordinates(jnp.concatenate([xr, rest]), scene, inst, t=None if steady else tt)

        return q, v, gamma, jax.jacfwd(phi_r)(qi[:nr]), F
    return _full_motion(qi, qi_dot, scene, inst, speed, t)


def _full_motion(qi, qi_dot, scene: Scene, inst: Installation, speed=0.0, t=None, skip_jacobian=False):
    steady = t is None
    t = jnp.zeros((), dtype=qi.dtype) if steady else jnp.asarray(t, dtype=qi.dtype)
    one = jnp.zeros_like(t) if steady else jnp.ones_like(t)  # the time's tangent
    phi = lambda x, tt: full_coordinates(x, scene, inst, t=None if steady else tt)  # noqa: E731
    rate = lambda x, tt: jax.jvp(phi, (x, tt), (qi_dot, one))[1]  # noqa: E731
    q, v = jax.jvp(phi, (qi, t), (qi_dot, one))
    if flexible(scene):
        _, gamma = jax.jvp(rate, (qi, t), (qi_dot, one))
    else:
        # massless spans (bars): their end nodes' accelerations carry no inertia, so only the
        # bodies' convective accelerations are formed (the span part would be multiplied by zero
        # mass; with a tensioner it is the second derivative of the tangent geometry)
        ns = n_span_coordinates(scene)
        body_rate = lambda x, tt: rate(x, tt)[ns:]  # noqa: E731
        _, gamma_b = jax.jvp(body_rate, (qi, t), (qi_dot, one))
        gamma = jnp.concatenate([jnp.zeros(ns, dtype=q.dtype), gamma_b])
    J = None if skip_jacobian else jax.jacfwd(phi)(qi, t)
    if steady:
        F = full_forces(q, v, scene, inst, transport_speed(scene, inst, speed))
    else:
        c, c_dot = transient_transport_speed(scene, inst, v, t)
        F = full_forces(q, v, scene, inst, c, c_dot, t=t)
    return q, v, gamma, J, F


def reduced_system(qi, qi_dot, scene: Scene, inst: Installation, speed=0.0, M_full=None, t=None):
    """Reduced mass matrix and forces: ``M_ii = J^T M J``, ``F_ii = J^T (F - M gamma)``.

    qi, qi_dot: independent coordinates and rates; speed: belt speed (m/s) when ``t`` is
    None (steady motion).  t: time (s) of a transient: the map is then Phi(q_i, t), the
    belt speed and its rate follow :func:`belt_travel`, and the damping effects and loads
    act.  Returns (M_ii, F_ii) in kg / kg m^2 and N / N m.
    """
    M = full_mass_matrix(scene, inst) if M_full is None else M_full
    q, v, gamma, J, F = full_motion(qi, qi_dot, scene, inst, speed, t)
    return with_travel_inertia(J.T @ M @ J, J.T @ (F - M @ gamma), J, travel_inertia(q, v, gamma, scene, inst, t))


def span_coordinate_index(scene: Scene) -> np.ndarray:
    """Position in the full vector q of each span coordinate of q_i (q_i order after the rigid ones).

    :func:`full_coordinates` copies the span coordinates of q_i (end slopes, interior nodes)
    into q unchanged, so ``dPhi/dq_i`` is, on these columns, the constant selection
    ``J[idx[k], n_rigid + k] = 1`` (zero elsewhere), whatever q_i and t.  Empty for the
    rotational model.
    """
    if not flexible(scene):
        return np.zeros(0, dtype=int)
    n = len(scene.route.order)
    N = scene.model.elements_per_span
    local = np.r_[2 : 4 * N, 4 * N + 2 : 4 * N + 4]  # slopes of node 0, nodes 1..N-1, slopes of node N
    return (np.arange(n)[:, None] * 4 * (N + 1) + local[None, :]).reshape(-1)


class ReducedMass(NamedTuple):
    """What the structured solve of :func:`reduced_accelerations` keeps of a drive (per run).

    M_full: full mass matrix; M_s = M_full[idx] (rows of the span coordinates); chol: Cholesky
    factor (lower) of the constant span block M_ss = M_full[idx][:, idx] (None without spans);
    m_body: the diagonal of the bodies' block (:func:`body_masses`, kg, kg m^2); BC: the spans'
    transport matrices when the belt's travel follows a free drive pulley
    (:func:`span_transport_matrices`), else None.
    """

    M_full: jax.Array
    M_s: jax.Array | None
    chol: jax.Array | None
    m_body: jax.Array
    BC: tuple | None = None


def reduced_mass(scene: Scene, inst: Installation, M_full=None) -> ReducedMass:
    """The constant parts of M_ii = J^T M J for :func:`reduced_accelerations` (factor once per run)."""
    M = full_mass_matrix(scene, inst) if M_full is None else M_full
    ns = n_span_coordinates(scene)
    m_body = jnp.diagonal(M)[ns:]
    idx = span_coordinate_index(scene)
    if idx.size == 0:
        return ReducedMass(M, None, None, m_body)
    M_s = M[idx]
    BC = span_transport_matrices(scene, inst) if travel_follows_drive(scene) else None
    return ReducedMass(M, M_s, jnp.linalg.cholesky(M_s[:, idx]), m_body, BC)


def _small_matmul_tn(A, B):
    """A^T @ B for a tall A (n, k) and B (n,) or (n, m) with small k, m, as a fused multiply and
    sum (no dot call)."""
    if B.ndim == 1:
        return jnp.sum(A * B[:, None], axis=0)
    return jnp.sum(A[:, :, None] * B[:, None, :], axis=0)


def reduced_accelerations(qi, qi_dot, scene: Scene, inst: Installation, rm: ReducedMass, t=None, speed=0.0):
    """q_i'' = M_ii^-1 F_ii of :func:`reduced_system`, by the block structure of J (rad/s^2, m/s^2).

    J = [J_r | S]: the rigid columns J_r (autodiff, n_rigid tangents) and the constant
    selection S of the span coordinates (:func:`span_coordinate_index`).  Hence
    M_ii = [[J_r^T M J_r, J_r^T M S], [S^T M J_r, M_ss]] with the constant span block
    M_ss factored once (``rm``, :func:`reduced_mass`), F_ii = [J_r^T r, r[idx]] with
    r = F - M gamma, and the solve is by the Schur complement on the rigid coordinates:
    O(n^2) per call instead of forming J^T M J (O(n_full^2 n)) and an LU (O(n^3)).  Same
    equations as ``jnp.linalg.solve(*reduced_system(...))`` to round-off.  The rotational
    model (massless bars) goes by the span lengths instead: :func:`_bar_accelerations`.
    """
    if not flexible(scene):
        return _bar_accelerations(qi, qi_dot, scene, inst, rm, t, speed)
    nr = n_rigid(scene)
    idx = span_coordinate_index(scene)
    q, v, gamma, J_r, F = full_motion(qi, qi_dot, scene, inst, speed, t, rigid_only=True)
    M = rm.M_full
    r = F - M @ gamma
    F_r = J_r.T @ r
    M_rr = J_r.T @ (M @ J_r)
    # a free drive pulley's travel: its coupling reaches only the rigid rows (k < n_rigid) and
    # the span rows' column k (S^T P = P[idx]); the span block M_ss stays constant
    ti = travel_inertia(q, v, gamma, scene, inst, t, rm.BC)
    M_rr, F_r = with_travel_inertia(M_rr, F_r, J_r, ti)
    if idx.size == 0:
        return _small_spd_solve(M_rr, F_r)
    F_s = r[idx]
    M_sr = rm.M_s @ J_r  # (n_span, n_rigid)
    if ti is not None:
        M_sr = M_sr.at[:, ti.k].add(ti.kappa * ti.P[idx])
    X = jax.scipy.linalg.cho_solve((rm.chol, True), jnp.concatenate([M_sr, F_s[:, None]], axis=1))
    if nr == 0:
        return X[:, 0]
    S_c = M_rr - M_sr.T @ X[:, :nr]
    b = F_r - M_sr.T @ X[:, nr]
    a_r = _small_spd_solve(S_c, b)
    return jnp.concatenate([a_r, X[:, nr] - X[:, :nr] @ a_r])


def _bar_accelerations(qi, qi_dot, scene: Scene, inst: Installation, rm: ReducedMass, t=None, speed=0.0):
    """:func:`reduced_accelerations` of the rotational model (rad/s^2), from the span lengths.

    Its spans are massless bars: their nodes carry no inertia, and their forces reach q_i
    only through the span lengths l(q_i) (:func:`span_lengths`, the same kinematic map), so
    F_ii = J_b^T (F_b - M_b gamma_b) - (dl/dq_i)^T (N + CA/L0 dl/dt) with the bodies' rows
    J_b of J and the bars' axial forces N = dV/dl (Green-Lagrange, less the centrifugal
    term: :func:`_bar_energy`).  Same equations as the general path to round-off
    (tests/test_fast_paths.py), about 4x cheaper on the tensioner bench: the span nodes'
    coordinates and their derivatives are never formed.
    """
    steady = t is None
    tt = jnp.zeros((), dtype=qi.dtype) if steady else jnp.asarray(t, dtype=qi.dtype)
    one = jnp.zeros_like(tt) if steady else jnp.ones_like(tt)

    def bodies(x, time):
        phi, theta = angles_and_arm(x, scene, inst)
        centers, _ = _centers(theta, scene, inst)
        return _body_coordinates(phi, theta, centers, scene, inst, None if steady else time)

    b, b_dot = jax.jvp(bodies, (qi, tt), (qi_dot, one))
    _, gamma_b = jax.jvp(lambda x, time: jax.jvp(bodies, (x, time), (qi_dot, one))[1], (qi, tt), (qi_dot, one))
    J_b = jax.jacfwd(bodies)(qi, tt)
    l, J_l = span_lengths_and_jacobian(qi, scene, inst)
    B, B_dot = b.reshape(-1, 3), b_dot.reshape(-1, 3)
    if steady:
        c = transport_speed(scene, inst, speed)
    else:  # the drive pulley's actual rim speed, as transient_transport_speed
        c = _rim_transport_speed(scene, inst, B_dot)
    L0 = element_length(scene, inst)
    cc = c if scene.model.has("transport") else 0.0
    N = jax.vmap(jax.grad(_bar_energy_l2), in_axes=(0, 0, None, None, None))(l * l, L0, scene.belt.EA, scene.belt.rhoA,
                                                                            cc) * (2 * l)
    if not steady and scene.model.has("belt_damping"):
        N = N + scene.belt.CA / L0 * jnp.sum(J_l * qi_dot, axis=1)
    F_b = body_forces(B, scene, inst, None if steady else B_dot, None if steady else tt).reshape(-1)
    F_i = _small_matmul_tn(J_b, F_b - rm.m_body * gamma_b) - _small_matmul_tn(J_l, N)
    return _small_spd_solve(_small_matmul_tn(J_b, rm.m_body[:, None] * J_b), F_i)


#: largest rigid block solved by the unrolled Gauss-Jordan elimination of :func:`_small_spd_solve`
UNROLLED_SOLVE_MAX = 8


def _small_spd_solve(A, b):
    """A^-1 b for a small symmetric positive definite A (a mass matrix of the rigid coordinates).

    Up to :data:`UNROLLED_SOLVE_MAX` unknowns by Gauss-Jordan elimination unrolled over the
    columns, each a whole-array update that XLA fuses (no pivoting: A is SPD, for which
    elimination without pivoting is stable).  The LAPACK calls of ``jnp.linalg.solve`` cost
    more in fixed overhead than the arithmetic at these sizes, and so does a scalar-unrolled
    Cholesky (a rotational drive's vector field is a microsecond or two, evaluated tens of
    thousands of times per simulated second).
    """
    n = A.shape[0]
    if n > UNROLLED_SOLVE_MAX:
        return jnp.linalg.solve(A, b)
    M = jnp.concatenate([A, b[:, None]], axis=1)
    rows = jnp.arange(n)[:, None]
    for k in range(n):
        pivot = M[k] / M[k, k]
        M = jnp.where(rows == k, pivot[None, :], M - M[:, k : k + 1] * pivot[None, :])
    return M[:, n]


def transient_transport_speed(scene: Scene, inst: Installation, v, t):
    """Transport speed c (m/s of unstretched belt) and the known part of its rate c_0' (m/s^2)
    at time t (s) of a transient, full coordinate rates v.

    c is the drive pulley's actual rim speed, c = s R theta' / lam (the thesis' c = R theta'),
    in both fidelities: the nominal travel's rate (:func:`belt_travel`) for a driven drive
    pulley, and for a free one (:func:`travel_follows_drive`) what its torque and the belt make
    of it, so that the centrifugal tension follows a crank turned by a torque.  c_0' is the
    nominal travel's acceleration / lam; a free drive pulley's own share, kappa phi_d''
    (:func:`travel_inertia`), belongs to the mass matrix of the hybrid model.
    """
    _, _, xdd = _travel_rates(scene, t)
    _, Bd = split_full(v, scene)
    return _rim_transport_speed(scene, inst, Bd), xdd / inst.stretch


def _travel_gain(scene: Scene, inst: Installation):
    """kappa = s R / lam (m/rad): the drive pulley's rim travel per radian, in unstretched belt."""
    d = drive_pulley(scene)
    return scene.route.senses[d] * inst.radii[d] / inst.stretch


def _rim_transport_speed(scene: Scene, inst: Installation, bodies_dot):
    """c = s R theta' / lam (m/s of unstretched belt) of the drive pulley; bodies_dot (nb, 3)."""
    return _travel_gain(scene, inst) * bodies_dot[drive_pulley(scene), 2]


class TravelInertia(NamedTuple):
    """The belt's travel as a degree of freedom (:func:`travel_inertia`).

    k: position of the free drive pulley's angle in q_i; kappa = s R / lam (m/rad): dc/d phi_d';
    pi_c = dT/dc (N s) is the spans' momentum conjugate to the transport speed; P = d pi_c / dq'
    (kg, full vector, zero on the bodies); pi_cc = d pi_c / dc (kg, the spans' belt mass times
    lam^2); h: the rate of pi_c at q_i'' = 0 (N).
    """

    k: int
    kappa: jax.Array
    P: jax.Array
    pi_cc: jax.Array
    h: jax.Array


def span_transport_matrices(scene: Scene, inst: Installation):
    """B = rhoA int N^T N' dx (kg/m times m over m: kg) and C = rhoA int N'^T N' dx (kg) of
    every span, each (n, 4 (N+1), 4 (N+1)): the spans' kinetic energy is
    1/2 e'^T M e' + c e'^T B e + 1/2 c^2 e^T C e (ancf.kinetic_energy), so its momentum
    conjugate to the transport speed is pi_c = e'^T B e + c e^T C e."""
    N = scene.model.elements_per_span
    idx = span.element_index(N)
    m = 4 * (N + 1)
    z = jnp.zeros(8)

    def one(L):
        Be = jax.jacfwd(ancf.momentum, argnums=0)(z, z, 1.0, scene.belt.rhoA, L)
        Ce = -ancf.centrifugal_matrix(1.0, scene.belt.rhoA, L)
        rows, cols = idx[:, :, None], idx[:, None, :]
        B = jnp.zeros((m, m)).at[rows, cols].add(jnp.broadcast_to(Be, (N, 8, 8)))
        C = jnp.zeros((m, m)).at[rows, cols].add(jnp.broadcast_to(Ce, (N, 8, 8)))
        return B, C

    return jax.vmap(one)(element_length(scene, inst))


def travel_inertia(q, v, gamma, scene: Scene, inst: Installation, t, BC=None) -> TravelInertia | None:
    """Inertia of the belt's travel when it follows a free drive pulley (hybrid transients).

    With c = c_0(t) + kappa phi_d' (:func:`transient_transport_speed`), the spans' kinetic
    energy T = sum 1/2 int rhoA |r_t + c r_x|^2 dx depends on phi_d' through c, so Lagrange's
    equations gain, besides the forces at this c: the rhoA dc/dt term's share kappa phi_d''
    (-P kappa phi_d'' on the span coordinates: mass coupling J^T P kappa e_k^T), and in the
    row of phi_d the rate of the momentum kappa pi_c, kappa (P . q'' + pi_cc c' + d pi_c/dq . q'),
    whose acceleration terms are the symmetric coupling and kappa^2 pi_cc (the spans' belt
    mass moving with the crank).  With pi_c = e'^T B e + c e^T C e
    (:func:`span_transport_matrices`, or ``BC`` precomputed): P = B e, pi_cc = e^T C e and
    h = gamma^T B e + e'^T B e' + 2 c e'^T C e + c_0' e^T C e.  None when the travel is
    prescribed (driven drive pulley, statics, modes) or the spans are massless (rotational
    model: there c alone follows).
    """
    if t is None or not flexible(scene) or not travel_follows_drive(scene):
        return None
    n = len(scene.route.order)
    ns = n_span_coordinates(scene)
    B, C = span_transport_matrices(scene, inst) if BC is None else BC
    c, c0_dot = transient_transport_speed(scene, inst, v, t)
    e, ed, g = (x[:ns].reshape(n, -1) for x in (q, v, gamma))
    Be = jnp.einsum("sij,sj->si", B, e)
    Ce = jnp.einsum("sij,sj->si", C, e)
    pi_cc = jnp.sum(e * Ce)
    h = jnp.sum(g * Be) + jnp.sum(ed * jnp.einsum("sij,sj->si", B, ed)) + 2 * c * jnp.sum(ed * Ce) + c0_dot * pi_cc
    kappa = _travel_gain(scene, inst)
    P_full = jnp.concatenate([Be.reshape(-1), jnp.zeros(q.shape[0] - ns, dtype=q.dtype)])
    return TravelInertia(travel_coordinate(scene), kappa, P_full, pi_cc, h)


def with_travel_inertia(M_ii, F_ii, J, ti: TravelInertia | None):
    """M_ii, F_ii of the reduced equations with the travel's inertia (:func:`travel_inertia`);
    J: dPhi/dq_i (n_full, n_i)."""
    if ti is None:
        return M_ii, F_ii
    a = J.T @ ti.P
    e = jnp.zeros_like(a).at[ti.k].set(1.0)
    M_ii = M_ii + ti.kappa * (jnp.outer(a, e) + jnp.outer(e, a)) + ti.kappa**2 * ti.pi_cc * jnp.outer(e, e)
    return M_ii, F_ii - ti.kappa * ti.h * e


def _travel_rates(scene: Scene, t):
    """Belt travel (m), speed (m/s) and acceleration (m/s^2) at time t (autodiff of belt_travel)."""
    f = lambda tt: belt_travel(scene, tt)  # noqa: E731
    d1 = lambda tt: jax.jvp(f, (tt,), (jnp.ones_like(tt),))[1]  # noqa: E731
    x, v = jax.jvp(f, (t,), (jnp.ones_like(t),))
    _, a = jax.jvp(d1, (t,), (jnp.ones_like(t),))
    return x, v, a


def static_residual(qi, scene: Scene, inst: Installation, speed=0.0):
    """Static (steady-motion) residual F_ii(q_i, 0) (N, N m); zero at equilibrium."""
    phi = lambda x: full_coordinates(x, scene, inst)  # noqa: E731
    q, vjp = jax.vjp(phi, qi)
    c = transport_speed(scene, inst, speed)
    F = full_forces(q, jnp.zeros_like(q), scene, inst, c)
    return vjp(F)[0]


# --------------------------------------------------------------------------- outputs at a state


def span_tension_profile(e, EA, Le, N):
    """Axial force EA eps |r'| (N) at each element's midpoint of a span, shape (N,)."""
    idx = span.element_index(N)

    def one(ee):
        rp = ancf.slope(ee, 0.5, Le)
        lam = jnp.sqrt(rp @ rp)
        return EA * 0.5 * (lam**2 - 1.0) * lam

    return jax.vmap(one)(e[idx])


def span_tensions(q, scene: Scene, inst: Installation):
    """Mean axial force of each span (N), route order."""
    E, _ = split_full(q, scene)
    Le = element_length(scene, inst)
    if not flexible(scene):
        lam = jnp.linalg.norm(E[:, 4:6] - E[:, 0:2], axis=1) / Le
        return scene.belt.EA * 0.5 * (lam**2 - 1.0) * lam
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
