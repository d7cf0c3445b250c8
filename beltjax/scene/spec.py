"""The scene as pytrees (equinox modules): belt, pulleys, tensioner, route, model, loads, initial
state and run settings; the reserved names and the choices a scene file may make."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import geometry
from beltjax.schema import default as _default
from beltjax.errors import BeltjaxError


#: effects a scene may ask for in ``model.effects`` (only listed ones are simulated)
EFFECTS = (
    "transport",  # axially moving belt: gyroscopic + centrifugal terms
    "gravity",  # weight of belt, pulleys and tensioner
    "belt_damping",  # viscous axial damping of the belt (belt.CA)
    "bearing_damping",  # viscous damping at pulley bearings (pulley.bearing_damping)
    "tensioner_damping",  # viscous damping at the tensioner pivot (tensioner.damping)
    "unbalance",  # pulley centre-of-mass offsets (pulley.cm_offset)
    "speed_fluctuation",  # harmonic fluctuation of a driven pulley's angle
    "tensioner_friction",  # dry (Coulomb) friction at the tensioner pivot
    "belt_slip",  # creep and gross slip of the belt on every wrapped arc (rotational model)
)


FIDELITIES = ("ancf", "rotational")


#: transient solvers (see beltjax.transient)
SOLVERS = ("generalized_alpha", "tsit5", "dopri8", "kvaerno5")


DIRECTIONS = geometry.DIRECTIONS


TENSIONER = "tensioner"  # the idler's name in route.order (reserved)


#: most ANCF elements per span (as ``beltjax span --elements``): more only exhausts memory
MAX_ELEMENTS_PER_SPAN = 400


ARM = "tensioner_arm"  # a [[torque]] on the tensioner's arm (about its pivot)


class SceneError(BeltjaxError):
    """Invalid scene: one-line message starting with the key path (``key`` attribute)."""

    def __init__(self, message: str = "", key: str = "", *, source: str = ""):
        super().__init__(message, key)
        self.source = source


class Belt(eqx.Module):
    """Belt section and installation (float64 array leaves).

    EA (N), EI (N m^2), rhoA (kg/m), CA (N s); exactly one of static_tension (N)
    and length (unstretched belt length, m) is an array, the other None.
    friction_coefficient (-): belt on pulley, or None (slip margins not assessed);
    groove_angle_deg (deg): a V or ribbed belt's groove angle (its wedge raises the friction
    of the pulleys it wraps with its ribs to mu / sin(angle / 2)), or None (a flat belt);
    slip_speed (m/s, effect ``belt_slip``): the gross-slip law's regularisation, the sliding
    speed at which an arc carries its capstan capacity at the installation tension beyond its
    capacity (:mod:`beltjax.drive.belt_slip`).
    """

    EA: jax.Array
    EI: jax.Array
    rhoA: jax.Array
    static_tension: jax.Array | None
    length: jax.Array | None
    CA: jax.Array
    friction_coefficient: jax.Array | None = None
    groove_angle_deg: jax.Array | None = None
    slip_speed: jax.Array = _default("belt.slip_speed")


class Pulley(eqx.Module):
    """A pulley on a fixed bearing.

    center (2,) m, radius m, mass kg, inertia kg m^2, speed_rpm rpm,
    acceleration_rpm_per_s rpm/s, fluctuation_amplitude_deg deg,
    fluctuation_frequency_hz Hz, cm_offset (2,) m, bearing_damping N m s/rad,
    target_speed_rpm rpm (the run-up's end speed) or None; friction_coefficient (-) of the
    belt on this pulley, or None (the belt's).
    """

    name: str = eqx.field(static=True)
    center: jax.Array
    radius: jax.Array
    mass: jax.Array
    inertia: jax.Array
    driven: bool = eqx.field(static=True)
    speed_rpm: jax.Array
    acceleration_rpm_per_s: jax.Array
    fluctuation_amplitude_deg: jax.Array
    fluctuation_frequency_hz: jax.Array
    cm_offset: jax.Array
    bearing_damping: jax.Array
    target_speed_rpm: jax.Array | None = None
    friction_coefficient: jax.Array | None = None


class Tensioner(eqx.Module):
    """Automatic tensioner: an arm on a pivot carrying an idler.

    pivot (2,) m, arm_length m, pulley_radius m, arm_mass kg, arm_inertia kg m^2
    (about the arm's centre of mass), pulley_mass kg, pulley_inertia kg m^2,
    spring_stiffness N m/rad, spring_preload_deg deg, arm_angle_deg deg or None,
    arm_cm_distance m, damping N m s/rad; dry friction at the pivot (effect
    ``tensioner_friction``): friction_moment N m, friction_asymmetry (-), friction_speed rad/s,
    friction_stick_time s;
    end stops: stop_min_deg / stop_max_deg deg or None, stop_stiffness N m/rad
    (:mod:`beltjax.drive.pivot`).
    """

    pivot: jax.Array
    arm_length: jax.Array
    pulley_radius: jax.Array
    arm_mass: jax.Array
    arm_inertia: jax.Array
    pulley_mass: jax.Array
    pulley_inertia: jax.Array
    spring_stiffness: jax.Array
    spring_preload_deg: jax.Array
    arm_angle_deg: jax.Array | None
    arm_cm_distance: jax.Array
    damping: jax.Array
    friction_moment: jax.Array = _default("tensioner.friction_moment")
    friction_asymmetry: jax.Array = _default("tensioner.friction_asymmetry")
    friction_speed: jax.Array = _default("tensioner.friction_speed")
    friction_stick_time: jax.Array = _default("tensioner.friction_stick_time")
    stop_min_deg: jax.Array | None = None
    stop_max_deg: jax.Array | None = None
    stop_stiffness: jax.Array = _default("tensioner.stop_stiffness")

    def idler_center(self, theta):
        """Idler centre (m), shape (2,), at arm angle theta (rad, CCW from +x)."""
        return geometry.tensioner_idler_center(self.pivot, self.arm_length, theta)


class Route(eqx.Module):
    """Belt route (static): order of travel, back-side pulleys, wrap direction."""

    order: tuple[str, ...] = eqx.field(static=True)
    back_side: tuple[str, ...] = eqx.field(static=True)
    direction: str = eqx.field(static=True)

    @property
    def span_names(self) -> list[str]:
        """Names of the spans in route order: "<from>-<to>" (span i leaves entry i)."""
        n = len(self.order)
        return [f"{self.order[i]}-{self.order[(i + 1) % n]}" for i in range(n)]

    @property
    def senses(self) -> np.ndarray:
        """Wrap sense per route entry: +1 CCW, -1 CW (numpy ints)."""
        return geometry.wrap_senses(self.order, self.back_side, self.direction)


class Model(eqx.Module):
    """Model choices (static)."""

    fidelity: str = eqx.field(static=True)
    elements_per_span: int = eqx.field(static=True)
    effects: tuple[str, ...] = eqx.field(static=True)
    bending: str = eqx.field(static=True)

    def has(self, effect: str) -> bool:
        """Whether ``effect`` (one of :data:`EFFECTS`) is switched on."""
        if effect not in EFFECTS:
            raise ValueError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
        return effect in self.effects


class Torque(eqx.Module):
    """A moment on a free pulley (N m, CCW positive) in a time window.

    M(t) = mean_Nm + amplitude_Nm sin(2 pi frequency_hz t + phase) for
    t_start_s <= t < t_end_s (s; t_end_s None = to the end), else 0.
    """

    pulley: str = eqx.field(static=True)
    mean_Nm: jax.Array
    amplitude_Nm: jax.Array
    frequency_hz: jax.Array
    phase_deg: jax.Array
    t_start_s: jax.Array
    t_end_s: jax.Array | None


class Fluctuation(eqx.Module):
    """One harmonic of the drive pulley's angle fluctuation (effect ``speed_fluctuation``).

    per "rev": amplitude_deg sin(rate alpha + phase), rate an order (cycles per revolution) and
    alpha the pulley's mean rotation since t = 0 (rad), so it follows the speed in run-ups;
    per "s": amplitude_deg sin(2 pi rate t + phase), rate a frequency (Hz).  A measured speed
    trace is read into such harmonics (``file``: where from, for reports; ``key``: the table).
    With ``rpm`` (increasing speeds, rpm) the amplitude is a table against the pulley's nominal
    speed (``amplitude_deg`` one value per speed, interpolated linearly, held beyond the ends).
    """

    pulley: str = eqx.field(static=True)
    per: str = eqx.field(static=True)
    rate: jax.Array
    amplitude_deg: jax.Array
    phase_deg: jax.Array
    file: str = eqx.field(static=True, default="")
    key: str = eqx.field(static=True, default="")  # the scene-file table, e.g. "fluctuation[1]"
    rpm: jax.Array | None = None

    def amplitude(self, speed_rpm):
        """The amplitude (deg) at the pulley's nominal speed ``speed_rpm`` (rpm)."""
        if self.rpm is None:
            return self.amplitude_deg
        return _interp_held(jnp.abs(speed_rpm), self.rpm, self.amplitude_deg)

    def angle(self, alpha, t, speed_rpm=None):
        """The fluctuation (rad) at mean rotation alpha (rad), time t (s) and nominal speed
        ``speed_rpm`` (rpm; needed only with an amplitude table)."""
        x = self.rate * alpha if self.per == "rev" else 2 * jnp.pi * self.rate * t
        return jnp.deg2rad(self.amplitude(speed_rpm)) * jnp.sin(x + jnp.deg2rad(self.phase_deg))


class Decoupler(eqx.Module):
    """An overrunning decoupler on a free pulley: the pulley (the scene's pulley, its own
    inertia) and a rotor (rotor_inertia, kg m^2) joined by a spring (stiffness, N m/rad) in series
    with a one-way clutch: the spring carries the pulley's lead over the rotor in the belt's
    direction of travel, k max(wind-up, 0), and the rotor overruns freely when it is ahead
    (:mod:`beltjax.drive.couplings`).  The pulley's [[torque]] loads act on the rotor."""

    pulley: str = eqx.field(static=True)
    rotor_inertia: jax.Array
    stiffness: jax.Array
    damping: jax.Array = _default("decoupler.damping")  # N m s/rad, across the spring while the clutch is engaged


class Isolator(eqx.Module):
    """A crank isolator (torsional isolator pulley): the driven drive pulley's rim (the scene's
    pulley, its inertia) on a spring (stiffness, N m/rad) and damper (damping, N m s/rad) to the
    hub, whose motion is the pulley's prescribed one (speed, run-up, fluctuation)
    (:mod:`beltjax.drive.couplings`)."""

    pulley: str = eqx.field(static=True)
    stiffness: jax.Array
    damping: jax.Array = _default("isolator.damping")


class SpanLoad(eqx.Module):
    """A harmonic force (N) on an interior node of a span, normal to the installed span
    (positive to the left of the belt's travel): F(t) = amplitude_N sin(2 pi frequency_hz t
    + phase) for t_start_s <= t < t_end_s (s)."""

    span: str = eqx.field(static=True)
    node: int = eqx.field(static=True)
    amplitude_N: jax.Array
    frequency_hz: jax.Array
    phase_deg: jax.Array
    t_start_s: jax.Array
    t_end_s: jax.Array | None


class Initial(eqx.Module):
    """Initial state of a transient, as a change from the static equilibrium: rotation_deg
    maps free pulleys to an added rotation (deg, CCW); arm_angle_deg is the tensioner arm's
    absolute initial angle (deg) or None.  The spans start straight between their moved ends."""

    rotation_deg: tuple[tuple[str, float], ...] = eqx.field(static=True, default=())
    arm_angle_deg: float | None = eqx.field(static=True, default=None)


class Simulation(eqx.Module):
    """Transient settings (static): solver name (None: :func:`beltjax.transient.default_solver`,
    by fidelity), step dt_s (s; fixed-step solvers and the first
    step of adaptive ones), rho_inf (generalized-alpha), rtol/atol (adaptive solvers),
    output_dt_s (s), output nodes ("<span>:<node>"; default each span's middle node),
    max_steps (adaptive solvers)."""

    solver: str | None = eqx.field(static=True, default=None)
    dt_s: float | None = eqx.field(static=True, default=None)
    rho_inf: float = eqx.field(static=True, default=_default("simulation.rho_inf"))
    rtol: float = eqx.field(static=True, default=_default("simulation.rtol"))
    atol: float = eqx.field(static=True, default=_default("simulation.atol"))
    output_dt_s: float | None = eqx.field(static=True, default=None)
    nodes: tuple[str, ...] | None = eqx.field(static=True, default=None)
    max_steps: int = eqx.field(static=True, default=_default("simulation.max_steps"))


class Scene(eqx.Module):
    """A validated drive: belt, pulleys (file order), optional tensioner, route, model."""

    belt: Belt
    pulleys: tuple[Pulley, ...]
    tensioner: Tensioner | None
    route: Route
    model: Model
    source: str = eqx.field(static=True, default="<dict>")
    description: str = eqx.field(static=True, default="")
    torques: tuple[Torque, ...] = ()
    span_loads: tuple[SpanLoad, ...] = ()
    fluctuations: tuple[Fluctuation, ...] = ()
    decouplers: tuple[Decoupler, ...] = ()
    isolator: Isolator | None = None
    initial: Initial = Initial()
    simulation: Simulation = Simulation()

    def pulley(self, name: str) -> Pulley:
        """The pulley called ``name`` (KeyError if none)."""
        for p in self.pulleys:
            if p.name == name:
                return p
        raise KeyError(name)

    def layout(self, arm_angle=None):
        """Centres (n, 2) m and radii (n,) m in route order (differentiable).

        arm_angle: tensioner arm angle (rad, CCW from +x); None uses
        ``tensioner.arm_angle_deg`` (ValueError if that is not given either).
        Ignored without a tensioner.
        """
        centers, radii = [], []
        for name in self.route.order:
            if name == TENSIONER:
                t = self.tensioner
                if arm_angle is None:
                    if t.arm_angle_deg is None:
                        raise ValueError("tensioner.arm_angle_deg: not given; pass arm_angle (rad)")
                    arm_angle = jnp.deg2rad(t.arm_angle_deg)
                centers.append(t.idler_center(arm_angle))
                radii.append(t.pulley_radius)
            else:
                p = self.pulley(name)
                centers.append(p.center)
                radii.append(p.radius)
        return jnp.stack(centers), jnp.stack(radii)

    def geometry(self, arm_angle=None, *, check: bool = True) -> geometry.DriveGeometry:
        """Belt path (:class:`beltjax.geometry.DriveGeometry`) at arm angle ``arm_angle`` (rad)."""
        centers, radii = self.layout(arm_angle)
        return geometry.drive_geometry(centers, radii, self.route.senses, names=self.route.order, check=check)


def require_scene(scene) -> Scene:
    """``scene`` if it is a :class:`Scene`, else a one-line :class:`SceneError` naming ``scene``
    (an analysis given a file name, a dict or None)."""
    if not isinstance(scene, Scene):
        raise SceneError(f"scene: expected a beltjax Scene (read a scene file with beltjax.scene.load_scene), got "
                         f"{type(scene).__name__}", "scene")
    if (bad := _leaf_problem(scene)) is not None:
        raise SceneError(bad[1], bad[0], source=scene.source)
    return scene


#: the scene's (x, y) leaves (m); every other number is a scalar, but a speed table's amplitudes
_XY = ("center", "cm_offset", "pivot")
#: the scene's tuples of tables -> the scene file's table name
_TABLES = {"pulleys": "pulley", "torques": "torque", "span_loads": "span_load", "fluctuations": "fluctuation",
           "decouplers": "decoupler"}


def _leaf_problem(scene: Scene) -> tuple[str, str] | None:
    """(scene-file key, message) of the first number of ``scene`` that is not a real number of its
    shape (a scalar, an (x, y) pair, or a speed table's equal-length rows), else None.  A scene
    built or changed through the Python API (``eqx.tree_at``, ``dataclasses.replace``) meets this
    before any analysis (the file's parser never makes one).  Shapes only: traced leaves pass
    unless their shape is wrong."""
    for path, leaf in jax.tree_util.tree_flatten_with_path(scene)[0]:
        parts, k, fluct = [], 0, None
        while k < len(path):
            name = getattr(path[k], "name", None)
            if name in _TABLES and k + 1 < len(path) and hasattr(path[k + 1], "idx"):
                i = path[k + 1].idx
                fluct = scene.fluctuations[i] if name == "fluctuations" else None
                parts.append((fluct.key if fluct is not None else "") or f"{_TABLES[name]}[{i}]")
                k += 2
                continue
            parts.append(str(name if name is not None else getattr(path[k], "idx", path[k])))
            k += 1
        key, field = ".".join(parts), parts[-1]
        kind = getattr(getattr(leaf, "dtype", None), "kind", None) or np.asarray(leaf).dtype.kind
        if kind not in "biuf":
            return key, f"{key}: must be a real number, got {type(leaf).__name__} of kind {kind!r}"
        shape = tuple(np.shape(leaf))
        want: tuple = (2,) if field in _XY else ()
        if fluct is not None and fluct.rpm is not None and field in ("amplitude_deg", "rpm"):
            want = tuple(np.shape(fluct.rpm)) if np.ndim(fluct.rpm) == 1 else (-1,)
        if shape != want:
            what = ("an (x, y) pair" if want == (2,) else "a number" if want == ()
                    else f"a row of numbers, one per speed of its rpm row ({want[0]})" if want[0] >= 0
                    else "a row of speeds")
            return key, f"{key}: must be {what}, got an array of shape {shape}"
    return None


def drive_pulley_index(pulleys, names=None) -> int:
    """Index in ``pulleys`` (a sequence of :class:`Pulley`) of the drive pulley, whose speed sets
    the belt's: the first driven one in file order, else the first; only the pulleys named in
    ``names`` (e.g. the route's order) count where given.  The one statement of that rule."""
    counted = [i for i, p in enumerate(pulleys) if names is None or p.name in names]
    return next((i for i in counted if pulleys[i].driven), counted[0] if counted else 0)


def _interp_held(x, xp, fp):
    """Piecewise-linear interpolation of the table (xp increasing, fp) at x, held beyond its ends:
    ``jnp.interp``'s values as a sum of one clipped ramp per segment,
    fp_0 + sum_k (fp_k+1 - fp_k) clip((x - xp_k) / (xp_k+1 - xp_k), 0, 1), elementwise over the
    segments and one sum, so that XLA fuses it (``jnp.interp``'s search compiled to while loops,
    and a gather by the found index to a dozen scalar kernels, in every evaluation of a
    rotational vector field; the tables are a few speeds long)."""
    ramps = jnp.clip((x - xp[:-1]) / (xp[1:] - xp[:-1]), 0.0, 1.0)
    return fp[0] + jnp.sum((fp[1:] - fp[:-1]) * ramps)
