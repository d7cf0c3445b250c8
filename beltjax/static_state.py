"""The user-facing static state of a drive: the operating point under the scene's mean loads, or
the unloaded state, with tensions, hub loads, the drive torque and the slip margins (SI units)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np

from beltjax import critical, drive, schema
from beltjax.drive import Installation, couplings, pivot
from beltjax.scene import TENSIONER, Scene
from beltjax.drive.effects import effects_of
from beltjax.statics import StaticsError, check_installation, check_solved, solve_at


@dataclass
class StaticResult:
    """Static state of a drive (SI units; route order); see :func:`analyse_statics`.

    span_names; span_tensions_N: mean axial force per span; span_lengths_m: between the model's
    end nodes (points of the belt, which the pulleys' turns slide along the span off the tangent
    points: :func:`beltjax.drive.end_slides`);
    span_free_lengths_m: tangent to tangent (a real span's; ``length_note`` says when the hybrid
    model's end nodes sit far from the tangent points);
    belt_length_m: unstretched belt length; installation_tension_N; stretch;
    hub_forces_N: force of the belt on each hub {name: [Fx, Fy]} (the tensioner
    idler as "tensioner"); tensioner_angle_deg, spring_moment_Nm,
    tensioner_pivot_force_N, arm_balances_deg: every stable arm angle that balances the installed
    belt (None without a tensioner); wrap_angles_deg: of the solved layout
    (the arm's swing from its installed angle turns them);
    speed_m_s; converged, iterations; span_forces_N: each span's force on the pulleys,
    tension less rhoA c^2 lam (:mod:`beltjax.critical`); supercritical: None, or the
    one-line reason why the state is past the critical speed (only with
    ``analyse_statics(..., allow_supercritical=True)``).  state: "operating point" (the
    scene's mean loads act) or "unloaded"; drive_torque_Nm: the torque the drive pulley's shaft
    applies (N m, CCW positive); loads_Nm: the mean load on each body (N m); unloaded: the
    unloaded state's :meth:`to_json` at the same speed (with the operating point); friction:
    per route entry the wrap, the friction the arc needs and has and the slip margin
    (:mod:`beltjax.friction`); slipping: the entries whose arcs would slip; decouplers: per
    decoupled pulley the spring's wind-up (deg, the pulley's lead over its rotor) and moment (N m).
    """

    span_names: list[str]
    span_tensions_N: np.ndarray
    span_lengths_m: np.ndarray
    belt_length_m: float
    installation_tension_N: float
    stretch: float
    hub_forces_N: dict
    wrap_angles_deg: dict
    speed_m_s: float
    tensioner_angle_deg: float | None
    spring_moment_Nm: float | None
    tensioner_pivot_force_N: list | None
    iterations: int
    qi: np.ndarray = field(repr=False)
    q: np.ndarray = field(repr=False)
    inst: Installation = field(repr=False)
    span_forces_N: np.ndarray | None = None
    supercritical: str | None = None
    state: str = "unloaded"
    drive_torque_Nm: float = float("nan")
    loads_Nm: dict = field(default_factory=dict)
    unloaded: dict | None = None
    friction: dict = field(default_factory=dict)
    decouplers: dict = field(default_factory=dict)
    arm_on_stop: str | None = None
    span_free_lengths_m: np.ndarray | None = None
    length_note: str | None = None
    arm_balances_deg: list | None = None
    arm_note: str | None = None

    @property
    def warnings(self) -> list[str]:
        """One line per thing the state's reader must know: arcs that would slip
        (:func:`beltjax.friction.slip_warning`), an arm that balances the installed belt at more
        than one angle (``arm_note``), the arm pressed into an end stop, hybrid spans
        whose end nodes sit far from their tangent points (``length_note``)."""
        from beltjax import friction

        lines = [friction.slip_warning(self.friction, self.state)]
        return [x for x in lines + [self.arm_note, self.arm_on_stop, self.length_note] if x]

    @property
    def slipping(self) -> list[str]:
        """Route entries whose arcs would slip (slip margin < 0)."""
        from beltjax import friction

        return friction.slipping(self.friction)

    def to_json(self) -> dict:
        """statics.json contents."""
        d = {
            "state": self.state,
            "span_names": self.span_names,
            "span_tensions_N": [float(x) for x in self.span_tensions_N],
            "span_forces_N": None if self.span_forces_N is None else [float(x) for x in self.span_forces_N],
            "span_lengths_m": [float(x) for x in self.span_lengths_m],
            "span_free_lengths_m": (None if self.span_free_lengths_m is None
                                    else [float(x) for x in self.span_free_lengths_m]),
            "belt_length_m": self.belt_length_m,
            "installation_tension_N": self.installation_tension_N,
            "stretch": self.stretch,
            "hub_forces_N": {k: [float(v[0]), float(v[1])] for k, v in self.hub_forces_N.items()},
            "hub_force_magnitudes_N": {k: float(np.hypot(*v)) for k, v in self.hub_forces_N.items()},
            "wrap_angles_deg": self.wrap_angles_deg,
            "speed_m_s": self.speed_m_s,
            "drive_torque_Nm": self.drive_torque_Nm,
            "loads_Nm": self.loads_Nm,
            "friction": self.friction,
            "slipping": self.slipping,
            "newton_iterations": self.iterations,
        }
        if self.tensioner_angle_deg is not None:
            d["tensioner_angle_deg"] = self.tensioner_angle_deg
            d["spring_moment_Nm"] = self.spring_moment_Nm
            d["tensioner_pivot_force_N"] = self.tensioner_pivot_force_N
            d["arm_balances_deg"] = self.arm_balances_deg
        if self.decouplers:
            d["decouplers"] = self.decouplers
        if self.arm_on_stop:
            d["arm_on_stop"] = self.arm_on_stop
        if self.unloaded is not None:
            d["unloaded"] = self.unloaded
        return d


def analyse_statics(scene: Scene, speed: float | None = None, *, allow_supercritical: bool = False,
                    loaded: bool | None = None, with_unloaded: bool = True) -> StaticResult:
    """Static state of the drive at belt speed ``speed`` (m/s; default from speed_rpm).

    loaded: the operating point, under the scene's mean loads (each lasting [[torque]]'s mean,
    the listed bearing drag at the steady speeds: :func:`beltjax.drive.mean_body_loads`), with
    the unloaded state at the same speed in ``unloaded``; False: the unloaded state only;
    None (default): the operating point when the scene has mean loads, else the unloaded state.
    with_unloaded: also solve the unloaded state beside an operating point (its own compiled
    statics: the analyses that need only the operating point leave it out).

    Raises :class:`StaticsError` (one line) when the belt cannot be fitted, the
    Newton iteration fails even with speed stepping, a span would go slack, or the
    speed is past the drive's critical speed (a span's force on the pulleys, tension
    less rhoA c^2 lam, <= 0: :mod:`beltjax.critical`; the line names the span, the speed
    and the critical speed).  With ``allow_supercritical`` such a state is returned
    instead, with the reason in ``supercritical`` (for the modal analysis, which reports
    it as unstable, and the transients, which record it).  A scene that fails the scene
    file's checks (:func:`beltjax.validate.check_scene`) or a speed that is NaN, infinite,
    negative or beyond 1e4 m/s is a one-line :class:`beltjax.errors.BeltjaxError`.  An arc
    whose friction would not carry the state is reported in ``slipping`` (not an error).
    """
    from beltjax import validate

    validate.check_scene(scene)
    for name, given in (("allow_supercritical", allow_supercritical), ("with_unloaded", with_unloaded)):
        validate.flag(given, name)
    validate.flag(loaded, "loaded", allow_none=True)
    v = float(drive.belt_speed(scene)) if speed is None else schema.number(speed, "speed", "drive.speed")
    scene = drive.statics_scene(scene)  # one compiled statics per drive, whatever its transient tables
    if loaded is None:
        loaded = drive.has_mean_loads(scene)
    # the installation is checked as it comes out of the statics' own program (no compilation of its own)
    res = _state(scene, v, loaded, allow_supercritical, check=lambda inst: check_installation(scene, inst))
    if loaded and with_unloaded:
        res.unloaded = _state(scene, v, False, True).to_json()
    return res


def _state(scene: Scene, v: float, loaded: bool, allow_supercritical: bool, check=None) -> StaticResult:
    """:func:`analyse_statics` of a checked, canonical scene at belt speed v (m/s); check: see
    :func:`beltjax.statics.solve_at`."""
    from beltjax import friction

    what = "operating point" if loaded else "unloaded state"
    out, conv, it, rn = solve_at(scene, v, loaded, check)
    if not conv:
        vc = critical.critical_speed(scene, v) if v != 0.0 else None
        if vc is not None:
            raise StaticsError(critical.message(scene, abs(v), vc, None, None))
        raise StaticsError(f"no static equilibrium found for the {what} (Newton stalled at residual {rn:.3g})",
                           "statics")
    names = drive.span_names(scene)
    tensions = np.asarray(out["tensions"])
    for nm, T in zip(names, tensions):
        if not T > 0:
            vc = critical.critical_speed(scene, v) if v != 0.0 else None
            if vc is not None:  # past the critical speed even unloaded: that is the cause, not the loads
                raise StaticsError(critical.message(scene, abs(v), vc, None, None))
            because = (": no belt could carry these loads at this installation tension (the pulleys at its ends "
                       "would need an infinite friction coefficient)" if loaded else "")
            raise StaticsError(f"span {nm} would go slack at the {what} (tension {T:.4g} N){because}", "statics")
    _check_operating(scene, out, names, what)
    forces = critical.output_forces(scene, out, v)
    reason = None
    if v != 0.0 and not np.all(forces > 0):
        vc = critical.critical_speed(scene, v)
        reason = critical.message(scene, abs(v), vc, forces, tensions)
        if not allow_supercritical:
            raise StaticsError(reason)
    order = scene.route.order
    bodies = drive.body_names(scene)
    hubs = np.asarray(out["hubs"])
    inst = out["inst"]
    check_solved(scene, float(inst.tension), math.degrees(float(out["theta"])) if scene.tensioner is not None else None)
    loads = np.asarray(out["loads"])
    wraps = np.asarray(out["wraps"])  # of the solved layout, not the installed one (the arm swings)
    res = StaticResult(
        span_names=names,
        span_tensions_N=tensions,
        span_lengths_m=np.asarray(out["lengths"]),
        span_free_lengths_m=np.asarray(out["free_lengths"]),
        length_note=_length_note(scene, names, np.asarray(out["end_slides"]), np.asarray(out["free_lengths"]), what),
        belt_length_m=float(inst.belt_length),
        installation_tension_N=float(inst.tension),
        stretch=float(inst.stretch),
        hub_forces_N={order[i]: hubs[i] for i in range(len(order))},
        wrap_angles_deg={order[i]: float(np.degrees(wraps[i])) for i in range(len(order))},
        speed_m_s=v,
        tensioner_angle_deg=None,
        spring_moment_Nm=None,
        tensioner_pivot_force_N=None,
        iterations=int(it),
        qi=np.asarray(out["qi"]),
        q=np.asarray(out["q"]),
        inst=inst,
        span_forces_N=forces,
        supercritical=reason,
        state="operating point" if loaded else "unloaded",
        drive_torque_Nm=float(out["drive_torque"]),
        loads_Nm={bodies[i]: float(loads[i]) for i in range(len(bodies)) if loads[i] != 0.0},
        friction=friction.assess(scene, forces, wraps,
                                 np.asarray(out["lengths"]) / (np.asarray(inst.span_length) / float(inst.stretch)),
                                 drive.drive_pulley(scene)),
    )
    worst = max(res.friction, key=lambda k: np.nan_to_num(res.friction[k]["friction_needed"]))
    need = res.friction[worst]["friction_needed"]
    if loaded and need > schema.FIELDS["belt.friction_coefficient"].high:
        raise StaticsError(f"pulley {worst!r} would need a friction coefficient of {need:.3g} to carry the operating "
                           f"point: no belt could (at most {schema.FIELDS['belt.friction_coefficient'].high:g}); raise "
                           "the installation tension or the wrap, or lower the loads", "statics")
    if scene.tensioner is not None:
        th = float(out["theta"])
        res.tensioner_angle_deg = math.degrees(th)
        res.spring_moment_Nm = float(drive.spring_moment(th, scene))
        res.tensioner_pivot_force_N = tensioner_pivot_force(scene, hubs)
        res.arm_on_stop = _arm_on_stop(scene.tensioner, res.tensioner_angle_deg, what)
        res.arm_balances_deg = _arm_balances(scene, np.degrees(np.asarray(out["arm_balances"])), float(inst.tension))
        res.arm_note = _arm_note(scene.tensioner, res.arm_balances_deg, math.degrees(float(inst.arm_angle)))
    if scene.isolator is not None:  # the isolator's spring carries the drive torque
        lag = abs(float(couplings.isolator_lag(scene.isolator, res.drive_torque_Nm)))
        if lag > math.pi:
            raise StaticsError(f"the isolator's spring winds up by {math.degrees(lag):.4g} deg to carry the drive "
                               f"torque {res.drive_torque_Nm:.4g} N m at the {what}: beyond half a turn, no "
                               f"isolator's travel; give a stiffness of at least {abs(res.drive_torque_Nm) / math.pi:.3g} "
                               "N m/rad", "isolator.stiffness")
    if scene.decouplers:  # each decoupler's wind-up (the pulley's lead over its rotor) and moment
        w_all = couplings.static_windups(jnp.asarray(res.qi), scene, inst)
        for j, d in enumerate(scene.decouplers):
            w = float(w_all[j])
            if w < couplings.OVERRUN_WINDUP:  # the rotor carried ahead by its load: the clutch would overrun
                raise StaticsError(f"the mean load on {d.pulley!r} drives its decoupler's rotor ahead of the pulley "
                                   f"(wind-up {math.degrees(w):.3g} deg): the clutch would overrun and the rotor "
                                   "has no steady state; load a decoupled pulley against the belt's travel",
                                   f"decoupler[{j}].pulley")
            res.decouplers[d.pulley] = {"windup_deg": math.degrees(w),
                                        "moment_Nm": float(couplings.decoupler_moment(w, d.stiffness))}
    return res


def tensioner_pivot_force(scene: Scene, hubs) -> list[float]:
    """The force (N, x and y) the tensioner's pivot bearing carries in a static state: the belt's
    force on the idler (its row of ``hubs``, (n, 2) N in route order) plus, with gravity, the
    weight of the arm and idler.  The one rule of ``statics.json`` and the optimiser's reports."""
    f = np.array(hubs[scene.route.order.index(TENSIONER)], dtype=float)
    if "gravity" in effects_of(scene):
        t = scene.tensioner
        f[1] += drive.GRAVITY[1] * float(t.arm_mass + t.pulley_mass)
    return [float(f[0]), float(f[1])]


def _check_operating(scene: Scene, out: dict, names: list[str], what: str) -> None:
    """Raise :class:`StaticsError` (one line) when the solved state ``out`` (:func:`beltjax.statics.
    static_outputs`) is past what any belt drive carries (:func:`beltjax.statics.operating_faults`):
    a span stretched beyond the installation's limit, or the tensioner arm wound round."""
    from beltjax.statics import MAX_ARM_SWING, MAX_INSTALL_STRAIN

    faults = {k: bool(f) for k, f in out["faults"].items()}
    loaded = what == "operating point"
    loads = "the mean loads ([[torque]] mean_Nm, bearing drag)"
    key = "torque" if loaded else "statics"
    if faults["arm_wound"]:
        a, a0 = math.degrees(float(out["theta"])), math.degrees(float(out["inst"].arm_angle))
        raise StaticsError(f"the tensioner arm would turn to {a:.5g} deg at the {what}, {abs(a - a0):.4g} deg from its "
                           f"installed {a0:.4g} deg: more than {math.degrees(MAX_ARM_SWING):g} deg, beyond any "
                           + (f"tensioner's travel; {loads} are far more than the belt carries: lower them" if loaded
                              else "tensioner's travel"), key)
    if faults["span_overstretched"]:
        strain = np.asarray(out["strains"])
        j = int(np.argmax(strain))
        raise StaticsError(f"span {names[j]} would stretch {100 * strain[j]:.4g} % at the {what} (tension "
                           f"{float(out['tensions'][j]):.4g} N), beyond the {100 * MAX_INSTALL_STRAIN:g} % any belt "
                           "takes: lower " + (f"{loads} or " if loaded else "") + "the installation tension", key)


def _length_note(scene: Scene, names: list[str], slides, lengths, state: str) -> str | None:
    """The line saying that a span of the hybrid model has an end node more than
    :data:`beltjax.span_flags.END_SLIDE_FRACTION` of its length (``lengths``, m) from its tangent
    point in this ``state`` (``slides`` (n, 2) m: :func:`beltjax.drive.end_slides`), or None: its
    free length and transverse modes are approximate by that much (as a transient's
    :func:`beltjax.span_flags.displaced_span_ends`)."""
    from beltjax.span_flags import END_SLIDE_FRACTION

    size = np.max(np.abs(slides), axis=1)
    j = int(np.argmax(size / lengths))
    if scene.model.fidelity != "ancf" or not size[j] > END_SLIDE_FRACTION * lengths[j]:
        return None
    return (f"span {names[j]!r} of the hybrid model: its end nodes sit up to {1e3 * size[j]:.3g} mm "
            f"({100 * size[j] / lengths[j]:.3g} % of the span) from the tangent points at the {state} (the pulleys' "
            "turns under load carry them along the span), so the span's free length and transverse modes are "
            "approximate by that much")


def _arm_balances(scene: Scene, scan, tension: float) -> list[float]:
    """The stable arm angles (deg) of the scan ``scan`` (deg, NaN between:
    :func:`beltjax.statics.arm_balances`) where the layout holds (no idler overlapping a pulley,
    a belt path: :func:`beltjax.validate.solved_status` at the installation tension, N)."""
    from beltjax import validate

    found = sorted(float(x) for x in scan if np.isfinite(x))
    if len(found) < 2:  # the one found is the installation's, checked as such
        return found
    status, _ = validate.solved_status(scene, tension, np.asarray(found), n=len(found))
    return [x for x, st in zip(found, status) if st == "ok"]


def _arm_note(t, balances: list, installed: float) -> str | None:
    """The line saying that the tensioner arm balances the installed belt at more than one angle
    (``balances``, deg, :func:`beltjax.statics.arm_balances`) and which (``installed``, deg) the
    installation took, or None."""
    if len(balances) < 2:
        return None
    key = "arm_angle_deg" if t.arm_angle_deg is not None else "spring_preload_deg"
    others = ", ".join(f"{x:.4g}" for x in balances if abs(x - installed) > 0.5)
    if not others:  # (balances closer than the scan's resolution tell apart: one balance)
        return None
    return (f"the tensioner arm balances the installed belt at {len(balances)} angles: {installed:.4g} deg, taken "
            f"as nearest tensioner.{key} = {float(getattr(t, key)):.4g} deg, and {others} deg; give {key} near "
            "another to install the belt there")


def _arm_on_stop(t, angle_deg: float, state: str) -> str | None:
    """The line saying that the tensioner arm (at ``angle_deg``, deg) is pressed into one of its end
    stops in this ``state`` (:func:`beltjax.drive.pivot.stop_pressed`), or None: there the stop, not
    the spring, sets the belt's tension."""
    on = pivot.stop_pressed(t, angle_deg)
    if on is None:
        return None
    key, stop = on
    return (f"the tensioner arm rests on its end stop at the {state} ({angle_deg:.5g} deg, {abs(angle_deg - stop):.3g} "
            f"deg into tensioner.{key} = {stop:.5g} deg): the stop, not the spring, sets the belt's tension there")
