"""The kinematic map q = Phi(q_i) (the junction structure of the power-port picture): pulley
centres, span end nodes at their tangent points, body coordinates, span lengths and their
Jacobian (closed form for the rotational model's bars).  Units: m, rad."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from beltjax.scene import Scene
from beltjax.drive.topology import Installation, drive_pulley, is_free, n_rigid, n_span_coordinates, travel_follows_drive
from beltjax.drive.layouts import layout_of
from beltjax.drive.spans import spans_of
from beltjax.drive.effects import effects_of
from beltjax.drive.assembly import drive_of
from beltjax.drive import belt_slip


def _split(qi, scene: Scene):
    """q_i -> (rigid coordinates, span coordinates (n, per span) or None without any)."""
    nr = n_rigid(scene)
    k = spans_of(scene).independent
    if k == 0:
        return qi[:nr], None
    return qi[:nr], qi[nr:].reshape(len(scene.route.order), k)


def angles_and_arm(qi, scene: Scene, inst: Installation, driven_angle=0.0):
    """Pulley rotation perturbations (n,) rad in route order, and the arm angle (rad).

    driven_angle: rotation perturbation of the driven pulleys (rad), a scalar or (n,) in
    route order (entries of free pulleys ignored).
    """
    rigid, _ = _split(qi, scene)
    free = np.asarray(is_free(scene), dtype=bool)
    driven = jnp.broadcast_to(jnp.asarray(driven_angle, dtype=qi.dtype), (len(free),))
    # the k-th free pulley takes rigid[k]: one gather and one select, not a scalar per pulley
    k = np.clip(np.cumsum(free) - 1, 0, None)
    phis = jnp.where(free, rigid[k] if rigid.size else driven, driven)
    return phis, layout_of(scene).arm_angle(rigid, inst)


def arm_row(qi, scene: Scene, inst: Installation):
    """d theta / d q_i (n_i,; rad per rad): the tensioner arm angle's row of the kinematic map, the
    generalised force of a unit moment on the arm (a unit vector on the arm's coordinate)."""
    return jax.grad(lambda x: angles_and_arm(x, scene, inst)[1])(qi)


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
        speed = w0 + a * t
    else:
        wT = p.target_speed_rpm * rpm
        t_star = (wT - w0) / jnp.where(a == 0.0, 1.0, a)
        tau = jnp.minimum(t, t_star)
        angle = w0 * tau + 0.5 * a * tau**2 + wT * (t - tau)
        speed = w0 + a * tau
    angle = effects_of(scene).drive_angle(angle, p, t, scene, speed / rpm)
    return p.radius * angle


def n_reaction_points(scene: Scene) -> int:
    """Bearings whose reactions are reported: one per route entry, plus the arm pivot."""
    return len(scene.route.order) + len(layout_of(scene).body_names)


def full_coordinates(qi, scene: Scene, inst: Installation, driven_angle=0.0, t=None, shift=None, slip=None):
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
    with it) and of its wrapped belt (on the axis).  slip: the belt's slip states (m,
    :mod:`beltjax.drive.belt_slip`, effect ``belt_slip``), sliding the span end nodes; None = 0.
    """
    model = spans_of(scene)
    _, spans = _split(qi, scene)
    phi, theta = angles_and_arm(qi, scene, inst, driven_angle)
    centers, radii = _centers(theta, scene, inst, shift)
    start, end, t_hat = _span_ends(phi, centers, radii, scene, inst, _travel(phi, radii, scene, t))
    if slip is not None and slip.size:
        s0, s1 = belt_slip.node_shifts(slip, len(scene.route.order))
        start, end = start + s0[:, None] * t_hat, end + s1[:, None] * t_hat
    nodes = jax.vmap(model.nodes, in_axes=(0, 0, 0, None if spans is None else 0, None))(
        start, end, t_hat, spans, inst.stretch)  # every span at once
    return jnp.concatenate([nodes.reshape(-1), _body_coordinates(phi, theta, centers, scene, inst, t, shift,
                                                                 rotor_angles(qi, scene))])


def _travel(phi, radii, scene: Scene, t):
    """The belt's travel beyond the nominal one (m): a free drive pulley's rim turn in a
    transient (time t, s) whose belt travels with it (:func:`travel_follows_drive`), else 0."""
    if t is None or not travel_follows_drive(scene):
        return 0.0
    d = drive_pulley(scene)
    return scene.route.senses[d] * radii[d] * phi[d]


def end_slides(qi, scene: Scene, inst: Installation, t=None):
    """How far (m) each span's start and end node sit from their tangent points, along the span,
    shape (n, 2): s R (phi - dpsi) - travel of :func:`_span_ends`.  The hybrid model's end nodes
    carry the belt's axial perturbation displacement there; t: time (s) of a transient, or None."""
    phi, theta = angles_and_arm(qi, scene, inst)
    centers, radii = _centers(theta, scene, inst)
    _, dpsi = _moved_tangents(centers, radii, scene, inst)
    return jnp.stack(_end_slides(phi, radii, dpsi, scene, _travel(phi, radii, scene, t)), axis=1)


def _end_slides(phi, radii, dpsi, scene: Scene, travel=0.0):
    """(start, end) slides (n,) m of every span's end nodes from its tangent points (:func:`_span_ends`)."""
    senses = jnp.asarray(scene.route.senses, dtype=radii.dtype)
    nxt = (np.arange(len(scene.route.order)) + 1) % len(scene.route.order)
    return senses * radii * (phi - dpsi) - travel, senses[nxt] * radii[nxt] * (phi[nxt] - dpsi) - travel


def rotor_angles(qi, scene: Scene):
    """Rotation perturbations (rad) of the decouplers' rotors (:mod:`beltjax.drive.couplings`):
    the rigid coordinates after the free pulleys'."""
    rigid, _ = _split(qi, scene)
    k = sum(is_free(scene))
    return rigid[k : k + len(scene.decouplers)]


def _centers(theta, scene: Scene, inst: Installation, shift=None):
    """Pulley centres (n, 2) m and radii (n,) m in route order at arm angle theta (rad),
    bearings shifted by ``shift`` (see :func:`full_coordinates`): the layout's
    (:func:`beltjax.drive.layouts.layout_of`)."""
    return layout_of(scene).centers(theta, scene, inst, shift)


def _span_ends(phi, centers, radii, scene: Scene, inst: Installation, travel=0.0):
    """Span end nodes (start, end, each (n, 2) m) and span directions (n, 2) of the kinematic
    map, for pulley rotation perturbations phi (n,) rad, centres (n, 2) m and radii (n,) m
    (:func:`_centers`); travel: the belt's travel beyond the nominal one (m), taken off every
    pulley's rim slide (the end nodes sit on the belt's Eulerian mesh, which moves with it).
    end - start is along the direction: the span's length is (end - start) . t_hat.

    The tangent points are the layout's (fixed centres: the installed ones; a tensioner: those
    of the moved layout, :func:`_moved_tangents`).  The belt on each arc turns with its pulley
    and gains s R dpsi where its end point moved by dpsi (rad, CCW) from the installed one, so
    each end node slides along its span by the rim travel less that, s R (phi - dpsi) - travel:
    spans and arcs then keep the belt's length exactly as an arm swings.
    """
    tl, dpsi = _moved_tangents(centers, radii, scene, inst)
    t_hat = tl.tangent
    s0, s1 = _end_slides(phi, radii, dpsi, scene, travel)
    s0 = s0 + inst.creep  # the belt its arc handed the span (running belt: Installation.creep)
    return tl.start + s0[:, None] * t_hat, tl.end + s1[:, None] * t_hat, t_hat


def _body_coordinates(phi, theta, centers, scene: Scene, inst: Installation, t=None, shift=None, rotors=None):
    """(x, y, angle) of every body, flattened (m, rad): pulleys in route order, the decouplers'
    rotors (on their pulleys' centres, turning by ``rotors`` (rad) beside their nominal rolling),
    then the arm (see :func:`full_coordinates`)."""
    senses = jnp.asarray(scene.route.senses, dtype=centers.dtype)
    rolling = 0.0 if t is None else senses * belt_travel(scene, t) / inst.radii
    angle = phi + rolling
    pos = effects_of(scene).body_positions(centers, angle, scene, inst)  # unbalance: centres of mass
    bodies = [jnp.concatenate([pos, angle[:, None]], axis=1).reshape(-1)]
    for j, i in enumerate(drive_of(scene).rotors):
        rot = rotors[j] + (0.0 if t is None else rolling[i])
        bodies.append(jnp.concatenate([centers[i], rot[None]]))
    return jnp.concatenate(bodies + layout_of(scene).bodies(theta, scene, shift))


def _moved_tangents(centers, radii, scene: Scene, inst: Installation):
    """Tangent lines of the layout with these centres (m) and radii (m), and how far each span's
    direction turned from the installed one, dpsi (n,) rad CCW (zero for fixed centres).  Both
    tangent points of a span lie on the normal to its direction, so each turned by dpsi on its
    pulley."""
    return layout_of(scene).tangents(centers, radii, scene, inst)


def span_lengths(qi, scene: Scene, inst: Installation):
    """Stretched span lengths (m), shape (n,): the distance between each span's end nodes in
    the kinematic map (:func:`full_coordinates`).  The rotational model's spans are bars of
    these lengths.

    In closed form: l = L + r dpsi + s' R' phi' - s R phi, with L the tangent length of the
    (moved) layout, r = s R - s' R' the signed radius difference of the span's pulleys (from
    ``s R`` to ``s' R'``) and dpsi (rad) how far the span's direction turned from the installed
    one (:func:`_moved_tangents`): the end slides of :func:`_span_ends` are s R (phi - dpsi) and
    s' R' (phi' - dpsi).  Less the belt each arc handed its exit span (``inst.creep``, m: a
    running belt's, zero as installed).
    """
    phi, theta = angles_and_arm(qi, scene, inst)
    centers, radii = _centers(theta, scene, inst)
    slides = _rim_slides(phi, radii, scene)
    sr = jnp.asarray(scene.route.senses, dtype=qi.dtype) * radii
    nxt = (np.arange(len(scene.route.order)) + 1) % len(scene.route.order)
    tl, dpsi = _moved_tangents(centers, radii, scene, inst)
    return tl.length + (sr - sr[nxt]) * dpsi + slides - inst.creep


def free_lengths(qi, scene: Scene, inst: Installation):
    """The spans' free lengths (n,) m at q_i: tangent point to tangent point of the layout moved by
    the arm (what a real span's transverse modes see).  :func:`span_lengths` differs by the
    two ends' :func:`end_slides`: the model's end nodes are points of the belt, which the pulleys'
    turns slide along the span off the tangent points."""
    _, theta = angles_and_arm(qi, scene, inst)
    centers, radii = _centers(theta, scene, inst)
    return _moved_tangents(centers, radii, scene, inst)[0].length


def wraps(qi, scene: Scene, inst: Installation):
    """Wrap angles (n,) rad of the layout at q_i: the installed ones, each turned by how far its
    exit span's direction turned less its entry span's, s (dpsi_i - dpsi_{i-1})
    (:func:`_moved_tangents`; the installed wraps for fixed centres)."""
    _, theta = angles_and_arm(qi, scene, inst)
    centers, radii = _centers(theta, scene, inst)
    _, dpsi = _moved_tangents(centers, radii, scene, inst)
    return inst.wrap + jnp.asarray(scene.route.senses, dtype=qi.dtype) * (dpsi - jnp.roll(dpsi, 1))


def _rim_slides(phi, radii, scene: Scene):
    """s' R' phi' - s R phi (m) per span: how much the pulley rotations phi (n,) rad lengthen
    each span (radii (n,) m, route order)."""
    sr = jnp.asarray(scene.route.senses, dtype=phi.dtype) * radii
    nxt = (np.arange(len(scene.route.order)) + 1) % len(scene.route.order)
    return sr[nxt] * phi[nxt] - sr * phi


def span_lengths_and_jacobian(qi, scene: Scene, inst: Installation):
    """:func:`span_lengths` (n,) m and their Jacobian dl/dq_i (n, n_i) (m/rad) of the rotational
    model.

    The rim slides are linear in the pulley angles and the layout moves with its own
    coordinates only (a tensioner's arm angle, the last rigid ones), so the Jacobian is the
    slides' (constant in q_i) plus one column per layout coordinate, each a forward pass (jvp)
    instead of one per coordinate (jacfwd), which matters in a vector field evaluated tens of
    thousands of times per simulated second.
    """

    def slides(x):
        phi, theta = angles_and_arm(x, scene, inst)
        return _rim_slides(phi, _centers(theta, scene, inst)[1], scene)

    J = jax.jacfwd(slides)(qi)
    nr, k = n_rigid(scene), layout_of(scene).coordinates
    if k == 0:  # fixed centres: linear in q_i
        return span_lengths(qi, scene, inst), J
    for j in range(nr - k, nr):
        e_j = jnp.zeros_like(qi).at[j].set(1.0)
        l, dl = jax.jvp(lambda x: span_lengths(x, scene, inst), (qi,), (e_j,))
        J = J + dl[:, None] * e_j[None, :]
    return l, J


def split_full(q, scene: Scene):
    """Full vector -> (spans (n, 4 (N+1)), bodies (nb, 3))."""
    ns = n_span_coordinates(scene)
    return q[:ns].reshape(len(scene.route.order), -1), q[ns:].reshape(-1, 3)


def installed_coordinates(scene: Scene, inst: Installation):
    """Independent coordinates of the installed drive: straight spans at the installation stretch."""
    return jnp.concatenate([jnp.zeros(n_rigid(scene)), spans_of(scene).installed(inst)])
