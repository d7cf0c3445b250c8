"""The channels a transient records at each output time: span tensions and forces, hub forces,
pulley speeds and angles, the arm, node displacements; their column labels and units (N, rpm, deg, m)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import critical, drive, friction
from beltjax.scene import Scene
from beltjax.drive import belt_slip, couplings
from beltjax.drive.effects import effects_of
from beltjax.span_flags import slipping_pulleys


def output_nodes(scene: Scene) -> list[tuple[int, int, str]]:
    """(span index, node, label) of the span nodes whose displacement is recorded."""
    if drive.spans_of(scene).independent == 0:  # bars: no interior nodes
        return []
    names = drive.span_names(scene)
    N = drive.spans_of(scene).elements
    chosen = scene.simulation.nodes
    if chosen is None:
        chosen = [f"{nm}:{N // 2}" for nm in names]
    out = []
    for x in chosen:
        nm, _, k = x.rpartition(":")
        out.append((names.index(nm), int(k), x))
    return out


def _outputs_one(t, y, scene: Scene, inst, M_full):
    """All output channels at one saved state (t s, y)."""
    n_i = drive.n_independent(scene)
    qi, qd, z = belt_slip.split_state(y, n_i)
    z = z if z.size else None
    n = len(scene.route.order)
    nrp = drive.n_reaction_points(scene)

    def phi(x, tt, shift, drv):
        return drive.full_coordinates(x, scene, inst, driven_angle=drv, t=tt, shift=shift, slip=z)

    shift0 = jnp.zeros((nrp, 2))
    drv0 = jnp.zeros(n)
    # q_i'' (and the slip rates) by the equations' own structured solve; J = [J_r | S] with
    # the constant selection S of the span coordinates (:func:`beltjax.drive.span_coordinate_index`)
    acc = drive.reduced_accelerations(qi, qd, scene, inst, drive.reduced_mass(scene, inst, M_full), t=t, slip=z)
    qdd, z_dot = acc if z is not None else (acc, None)
    q, v, gamma, J_r, F = drive.full_motion(qi, qd, scene, inst, t=t, slip=z, slip_rate=z_dot, rigid_only=True)
    ti = drive.travel_inertia(q, v, gamma, scene, inst, t)
    nr = J_r.shape[1]
    a = (J_r @ qdd[:nr] + gamma).at[drive.span_coordinate_index(scene)].add(qdd[nr:])
    if ti is not None:  # the rhoA dc/dt force of the travel's own acceleration
        F = F - ti.kappa * qdd[ti.k] * ti.P
    c = drive.transient_transport_speed(scene, inst, v, t)[0]
    R = F - M_full @ a  # applied minus inertial: what the constraints must balance
    # (F has no pivot friction, which acts through the accelerations: R carries minus its moment on
    # the arm's rotation, which no bearing shift or drive angle moves; the moment is reported below)
    # the bearings' reactions R . dPhi/dshift and the drives' holding torques -R . dPhi/d(driven
    # angle): one reverse pass for both (forward passes would take one per bearing axis and pulley)
    bearings, hold = jax.vjp(lambda s, d: phi(qi, t, s, d), shift0, drv0)[1](R)
    hold = -hold  # torque the drive applies to keep a driven pulley on its motion

    E, B = drive.split_full(q, scene)
    _, Bd = drive.split_full(v, scene)
    tensions = drive.span_tensions(q, scene, inst)
    lam = drive.full_span_lengths(q, scene) / (drive.element_length(scene, inst) * drive.span_elements(scene))
    pulley = critical.pulley_forces(tensions, lam, c, scene.belt.rhoA)  # whatever the effects
    forces = pulley if effects_of(scene).moving_belt else tensions
    phis, theta = drive.angles_and_arm(qi, scene, inst)
    out = dict(
        span_tensions_N=tensions,
        span_forces_N=forces,
        _pulley_forces_N=pulley,  # for the critical-speed check; not an output channel
        _wraps_rad=drive.wraps(qi, scene, inst),  # the present wraps, for the friction's margins; not a channel
        hub_forces_N=bearings,
        hub_force_magnitudes_N=jnp.linalg.norm(bearings, axis=1),
        pulley_speeds_rpm=Bd[:n, 2] * 60.0 / (2 * jnp.pi),
        pulley_rotations_deg=jnp.rad2deg(phis),
        drive_torques_Nm=hold,
        belt_speed_m_s=c * inst.stretch,
    )
    if scene.tensioner is not None:
        out["arm_angle_deg"] = jnp.rad2deg(theta)
        out["spring_moment_Nm"] = drive.spring_moment(theta, scene)
        if "tensioner_friction" in effects_of(scene):
            # the pivot's dry-friction moment acts through the accelerations, not in F: it is the
            # arm's generalised force left over, J^T R = -g M_f (g the arm's row; a rigid coordinate)
            g = drive.arm_row(qi, scene, inst)
            m_f = -g[:nr] @ (J_r.T @ R)
            out["pivot_friction_moment_Nm"] = m_f
            out["pivot_friction_power_W"] = -m_f * (g @ qd)  # the heat it makes
    if scene.isolator is not None:  # the isolator's moment on the crank's rim
        d = list(scene.route.order).index(scene.isolator.pulley)
        out["isolator_moment_Nm"] = couplings.isolator_moment(scene, B[d, 2], Bd[d, 2], t)
    if scene.decouplers:  # the rotors' speeds and the decoupler springs' moments
        rows = n + jnp.arange(len(scene.decouplers))
        out["rotor_speeds_rpm"] = Bd[rows, 2] * 60.0 / (2 * jnp.pi)
        stiff = jnp.stack([d.stiffness for d in scene.decouplers])
        out["decoupler_moments_Nm"] = couplings.decoupler_moment(couplings.windups(B[:n, 2], B[rows, 2], scene), stiff)
    if z is not None:  # the belt's sliding over each rim (gross slip, creep) and its friction power
        # creep: the belt an arc feeds its exit span beyond its rim's, u' + d' (the arc's belt replaced)
        out["slip_speeds_m_s"], out["creep_speeds_m_s"] = z_dot[:n], z_dot[n:2 * n] + z_dot[2 * n:]
        out["friction_power_W"] = belt_slip.dissipation(forces, z_dot, n)
    if drive.spans_of(scene).massive:  # the end nodes' offsets from the tangent points (not an output channel)
        out["_end_slides_m"] = drive.end_slides(qi, scene, inst, t)
    nodes = output_nodes(scene)
    if nodes:
        disp = []
        for s, k, _ in nodes:
            r = E[s, 4 * k : 4 * k + 2]
            N = scene.model.elements_per_span
            r0 = inst.span_start[s] + (k / N) * (inst.span_end[s] - inst.span_start[s])
            tan = inst.span_tangent[s]
            disp.append((r - r0) @ jnp.stack([-tan[1], tan[0]]))
        out["node_displacements_m"] = jnp.stack(disp)
    return out


@eqx.filter_jit
def _outputs(ts, ys, scene: Scene, inst):
    M_full = drive.full_mass_matrix(scene, inst)
    return jax.vmap(lambda t, y: _outputs_one(t, y, scene, inst, M_full))(ts, ys)


def _columns(scene: Scene) -> dict[str, list[str]]:
    order = list(scene.route.order)
    bearings = order + (["tensioner pivot"] if scene.tensioner is not None else [])
    cols = dict(
        span_tensions_N=drive.span_names(scene),
        span_forces_N=drive.span_names(scene),
        hub_forces_N=bearings,
        hub_force_magnitudes_N=bearings,
        pulley_speeds_rpm=order,
        pulley_rotations_deg=order,
        drive_torques_Nm=[n for n, f in zip(order, drive.is_free(scene)) if not f],
    )
    nodes = output_nodes(scene)
    if nodes:
        cols["node_displacements_m"] = [lab for _, _, lab in nodes]
    if scene.decouplers:
        cols["rotor_speeds_rpm"] = [f"{d.pulley} rotor" for d in scene.decouplers]
        cols["decoupler_moments_Nm"] = [d.pulley for d in scene.decouplers]
    if belt_slip.n_states(scene):
        cols["slip_speeds_m_s"] = cols["creep_speeds_m_s"] = list(scene.route.order)
    return cols


UNITS = dict(
    span_tensions_N="N",
    span_forces_N="N",
    hub_forces_N="N",
    hub_force_magnitudes_N="N",
    pulley_speeds_rpm="rpm",
    pulley_rotations_deg="deg",
    drive_torques_Nm="N m",
    belt_speed_m_s="m/s",
    arm_angle_deg="deg",
    spring_moment_Nm="N m",
    rotor_speeds_rpm="rpm",
    isolator_moment_Nm="N m",
    decoupler_moments_Nm="N m",
    node_displacements_m="m",
    friction_needed="-",
    slip_margins="-",
    slip_speeds_m_s="m/s",
    creep_speeds_m_s="m/s",
    friction_power_W="W",
    pivot_friction_moment_Nm="N m",
    pivot_friction_power_W="W",
)


def friction_channels(scene: Scene, wraps, pulley_forces, t, chans: dict, cols: dict) -> list[dict]:
    """Add the friction each arc needs (capstan law, :mod:`beltjax.friction`) over its present
    wrap (``wraps``, rad, (samples, n): an arm's swing turns the wraps of its idler and its
    neighbours) and, where the scene gives a friction coefficient, the slip margins to the
    channels; the pulleys whose margin fell to zero or below
    (:func:`beltjax.span_flags.slipping_pulleys`).  A span that carries nothing (slack or past
    the critical speed: flagged on its own) counts as 1e-9 N."""
    need, margins = friction.arc_margins(scene, pulley_forces, np.asarray(wraps), np)
    order = list(scene.route.order)
    chans["friction_needed"], cols["friction_needed"] = need, order
    given = friction.given(scene)
    if not given:
        return []
    chans["slip_margins"], cols["slip_margins"] = margins, [order[i] for i in given]
    slides = belt_slip.n_states(scene) > 0  # the run's belt slides where the limit is exceeded
    return [dict(r, slides=slides) for r in slipping_pulleys(t, margins, cols["slip_margins"])]
