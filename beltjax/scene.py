"""Scene files: reading and validating TOML drive descriptions into pytrees.

The format is the contract of ``DESIGN.md`` ("Scene files"); this module adds
only optional keys.  Units SI, angles in degrees where a key ends in ``_deg``,
speeds in rpm where it ends in ``_rpm``.  Tables and keys:

``[belt]``      EA (N), EI (N m^2), rhoA (kg/m); exactly one of static_tension (N)
                and length (unstretched, m).  Optional: CA (N s, viscous axial
                damping parameter of the thesis, span damping c = CA / L), default 0.
``[[pulley]]``  name, center [x, y] (m), radius (m), mass (kg), inertia (kg m^2);
                optional driven (bool, default false), speed_rpm (driven pulleys
                only, default 0).  Optional additions: acceleration_rpm_per_s and
                fluctuation_amplitude_deg / fluctuation_frequency_hz (driven
                pulleys only: theta(t) = theta0 + w t + a t^2 / 2 + A sin(2 pi f t),
                thesis eq. 4.62), cm_offset [x, y] (m, centre-of-mass offset in the
                pulley frame, the "unbalance" effect, thesis eq. 4.5),
                bearing_damping (N m s/rad), target_speed_rpm (driven only: the
                run-up holds this speed once reached).  All default to 0 / none.
                Signs: the belt runs in the route's direction; speed_rpm is its
                drive pulley's speed along that direction (its sign is ignored),
                acceleration > 0 speeds it up.
``[tensioner]`` optional; pivot [x, y] (m), arm_length (m), pulley_radius (m),
                arm_mass (kg), arm_inertia (kg m^2, about the arm's centre of mass),
                pulley_mass (kg), pulley_inertia (kg m^2), spring_stiffness
                (N m/rad), spring_preload_deg (the arm angle at zero spring moment).
                Optional additions: arm_angle_deg (initial guess / installed arm
                angle, CCW from +x, pivot -> idler), arm_cm_distance (m, pivot to
                the arm's centre of mass along the arm, default 0), damping
                (N m s/rad at the pivot, default 0).  Its idler is "tensioner" in
                the route.
``[route]``     order (names in the belt's direction of travel), back_side
                (default []), direction ("cw" default, or "ccw").
``[model]``     fidelity ("ancf" default, or "rotational"), elements_per_span
                (int, 1 to 400, default 16), effects (subset of :data:`EFFECTS`,
                default []), optional bending ("linear" default, or "exact").
``[[torque]]``  optional loads: pulley (a free route entry, or "tensioner_arm"), mean_Nm, amplitude_Nm,
                frequency_hz, phase_deg, t_start_s, t_end_s: a moment (N m, CCW
                positive) mean + amplitude sin(2 pi f t + phase) in [t_start, t_end).
``[[span_load]]`` optional (hybrid model only): span ("<from>-<to>"), node
                (interior, 1..N-1), amplitude_N, frequency_hz, phase_deg, t_start_s,
                t_end_s: a harmonic force normal to the installed span.
``[initial]``   optional transient start: rotation_deg = {pulley = deg} added to the
                static equilibrium, arm_angle_deg (absolute).
``[simulation]`` optional transient settings: solver (:data:`SOLVERS`; default by
                fidelity, see beltjax.transient.default_solver), dt_s,
                rho_inf, rtol, atol, output_dt_s, nodes (["<span>:<node>"]), max_steps.
Top level:      optional ``description`` (string).

An effect's parameter given while the effect is not in ``model.effects`` (belt.CA
without "belt_damping", cm_offset without "unbalance", ...) is an error, never
silently ignored.  Loads act when their tables are present; statics and modal
analysis ignore damping and loads (they are of the undamped, unloaded drive).

Every problem raises :class:`SceneError` (a ``ValueError``) with a one-line
message that starts with the key path, e.g. ``pulley[1].radius: must be > 0,
got -0.01`` (``pulley[i]`` counts the ``[[pulley]]`` tables from 0 in file
order); file-level problems start with the file name.

Every number must lie in its accepted range (below, from :mod:`beltjax.schema`: wide
enough for every real belt drive, inside what float64 carries), e.g. ``belt.EI: must lie
in [0, 100000] N m^2 (...), got 1e+20``; the whole drive then passes the layout checks and
the derived float64 limits of :mod:`beltjax.validate` (the same checks as a parameter set
with :mod:`beltjax.parameters`, a sweep case and the Python API).

The parsed :class:`Scene` is an equinox Module: every number is a float64 jax
array leaf (so ``jax.grad`` / ``eqx.filter_grad`` reach centres, radii,
stiffnesses...), names and switches are static fields.

"""

from __future__ import annotations

import functools
import math
import os
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import geometry, schema, textfile, tomltable
from beltjax.ancf import BENDING_MODELS
from beltjax.errors import BeltjaxError
from beltjax.tomltable import describe

if __doc__:  # (None under python -OO)
    __doc__ += schema.scene_doc()  # the accepted ranges: one source, beltjax.schema

#: effects a scene may ask for in ``model.effects`` (only listed ones are simulated)
EFFECTS = (
    "transport",  # axially moving belt: gyroscopic + centrifugal terms
    "gravity",  # weight of belt, pulleys and tensioner
    "belt_damping",  # viscous axial damping of the belt (belt.CA)
    "bearing_damping",  # viscous damping at pulley bearings (pulley.bearing_damping)
    "tensioner_damping",  # viscous damping at the tensioner pivot (tensioner.damping)
    "unbalance",  # pulley centre-of-mass offsets (pulley.cm_offset)
    "speed_fluctuation",  # harmonic fluctuation of a driven pulley's angle
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

    def __init__(self, message: str, key: str = "", source: str = ""):
        super().__init__(message)
        self.key = key
        self.source = source


# --------------------------------------------------------------------------- pytrees


class Belt(eqx.Module):
    """Belt section and installation (float64 array leaves).

    EA (N), EI (N m^2), rhoA (kg/m), CA (N s); exactly one of static_tension (N)
    and length (unstretched belt length, m) is an array, the other None.
    """

    EA: jax.Array
    EI: jax.Array
    rhoA: jax.Array
    static_tension: jax.Array | None
    length: jax.Array | None
    CA: jax.Array


class Pulley(eqx.Module):
    """A pulley on a fixed bearing.

    center (2,) m, radius m, mass kg, inertia kg m^2, speed_rpm rpm,
    acceleration_rpm_per_s rpm/s, fluctuation_amplitude_deg deg,
    fluctuation_frequency_hz Hz, cm_offset (2,) m, bearing_damping N m s/rad,
    target_speed_rpm rpm (the run-up's end speed) or None.
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


class Tensioner(eqx.Module):
    """Automatic tensioner: an arm on a pivot carrying an idler.

    pivot (2,) m, arm_length m, pulley_radius m, arm_mass kg, arm_inertia kg m^2
    (about the arm's centre of mass), pulley_mass kg, pulley_inertia kg m^2,
    spring_stiffness N m/rad, spring_preload_deg deg, arm_angle_deg deg or None,
    arm_cm_distance m, damping N m s/rad.
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
    rho_inf: float = eqx.field(static=True, default=0.9)
    rtol: float = eqx.field(static=True, default=1e-6)
    atol: float = eqx.field(static=True, default=1e-9)
    output_dt_s: float | None = eqx.field(static=True, default=None)
    nodes: tuple[str, ...] | None = eqx.field(static=True, default=None)
    max_steps: int = eqx.field(static=True, default=1_000_000)


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


# --------------------------------------------------------------------------- readers


def _fail(key, msg, source=""):
    raise SceneError(f"{key}: {msg}", key, source)


def _table(data, key: str, source: str, allowed: tuple[str, ...]) -> tomltable.Table:
    """A scene table being read (errors: :class:`SceneError` naming ``source``)."""
    return tomltable.Reader(functools.partial(_fail, source=source)).table(data, key, allowed)


def _arr(x):
    return None if x is None else jnp.asarray(x, dtype=jnp.float64)


_num = schema.read_number
_vec = schema.read_vector


# --------------------------------------------------------------------------- sections

_TOP_KEYS = (
    "description", "belt", "pulley", "tensioner", "route", "model", "torque", "span_load", "initial", "simulation"
)
_BELT_KEYS = ("EA", "EI", "rhoA", "static_tension", "length", "CA")
_PULLEY_KEYS = (
    "name",
    "center",
    "radius",
    "mass",
    "inertia",
    "driven",
    "speed_rpm",
    "acceleration_rpm_per_s",
    "fluctuation_amplitude_deg",
    "fluctuation_frequency_hz",
    "cm_offset",
    "bearing_damping",
    "target_speed_rpm",
)
_DRIVEN_ONLY = ("acceleration_rpm_per_s", "fluctuation_amplitude_deg", "fluctuation_frequency_hz", "target_speed_rpm")
_TORQUE_KEYS = ("pulley", "mean_Nm", "amplitude_Nm", "frequency_hz", "phase_deg", "t_start_s", "t_end_s")
_SPAN_LOAD_KEYS = ("span", "node", "amplitude_N", "frequency_hz", "phase_deg", "t_start_s", "t_end_s")
_INITIAL_KEYS = ("rotation_deg", "arm_angle_deg")
_SIMULATION_KEYS = ("solver", "dt_s", "rho_inf", "rtol", "atol", "output_dt_s", "nodes", "max_steps")
#: effect -> (what it needs, how to tell that the scene gives it)
_EFFECT_PARAMETERS = {
    "belt_damping": "belt.CA",
    "bearing_damping": "pulley[i].bearing_damping",
    "tensioner_damping": "tensioner.damping",
    "unbalance": "pulley[i].cm_offset",
    "speed_fluctuation": "pulley[i].fluctuation_amplitude_deg",
}
_TENSIONER_KEYS = (
    "pivot",
    "arm_length",
    "pulley_radius",
    "arm_mass",
    "arm_inertia",
    "pulley_mass",
    "pulley_inertia",
    "spring_stiffness",
    "spring_preload_deg",
    "arm_angle_deg",
    "arm_cm_distance",
    "damping",
)
_ROUTE_KEYS = ("order", "back_side", "direction")
_MODEL_KEYS = ("fidelity", "elements_per_span", "effects", "bending")


def _parse_belt(data, source) -> Belt:
    t = _table(data, "belt", source, _BELT_KEYS)
    EA = _num(t, "EA", "belt")
    EI = _num(t, "EI", "belt")
    rhoA = _num(t, "rhoA", "belt")
    if t.has("static_tension") == t.has("length"):
        _fail("belt", "give exactly one of static_tension and length", source)
    T = _num(t, "static_tension", "belt", required=False)
    L = _num(t, "length", "belt", required=False)
    CA = _num(t, "CA", "belt", required=False, default=0.0)
    return Belt(EA=_arr(EA), EI=_arr(EI), rhoA=_arr(rhoA), static_tension=_arr(T), length=_arr(L), CA=_arr(CA))


def _parse_pulley(data, i, source) -> Pulley:
    t = _table(data, f"pulley[{i}]", source, _PULLEY_KEYS)
    name = t.string("name")
    if not name.strip():
        t.fail("name", "must not be empty")
    if name == TENSIONER:
        t.fail("name", f"{TENSIONER!r} is reserved for the [tensioner] idler")
    center = _vec(t, "center", "pulley")
    radius = _num(t, "radius", "pulley")
    mass = _num(t, "mass", "pulley")
    inertia = _num(t, "inertia", "pulley")
    driven = t.boolean("driven")
    if not driven:
        for k in _DRIVEN_ONLY:
            if t.has(k):
                t.fail(k, "only a driven pulley (driven = true) takes a prescribed motion")
    speed = _num(t, "speed_rpm", "pulley", required=False, default=0.0)
    accel = _num(t, "acceleration_rpm_per_s", "pulley", required=False, default=0.0)
    amp = _num(t, "fluctuation_amplitude_deg", "pulley", required=False, default=0.0)
    freq = _num(t, "fluctuation_frequency_hz", "pulley", required=False, default=0.0)
    cm = _vec(t, "cm_offset", "pulley", required=False, default=[0.0, 0.0])
    if math.hypot(*cm) >= radius:
        t.fail("cm_offset", f"offset {math.hypot(*cm)!r} m must be smaller than the radius {radius!r} m")
    bd = _num(t, "bearing_damping", "pulley", required=False, default=0.0)
    target = _num(t, "target_speed_rpm", "pulley", required=False)
    if target is not None:
        if accel == 0.0:
            t.fail("target_speed_rpm", "needs acceleration_rpm_per_s (a run-up) to reach it")
        if (target - abs(speed)) * accel <= 0.0:
            t.fail(
                "target_speed_rpm",
                f"{target!r} rpm cannot be reached from {abs(speed)!r} rpm with acceleration {accel!r} rpm/s",
            )
    if amp > 0.0 and freq == 0.0:
        t.fail("fluctuation_frequency_hz", "missing (required with fluctuation_amplitude_deg > 0)")
    return Pulley(
        name=name,
        center=_arr(center),
        radius=_arr(radius),
        mass=_arr(mass),
        inertia=_arr(inertia),
        driven=driven,
        speed_rpm=_arr(speed),
        acceleration_rpm_per_s=_arr(accel),
        fluctuation_amplitude_deg=_arr(amp),
        fluctuation_frequency_hz=_arr(freq),
        cm_offset=_arr(cm),
        bearing_damping=_arr(bd),
        target_speed_rpm=_arr(target),
    )


def _parse_tensioner(data, source) -> Tensioner:
    t = _table(data, "tensioner", source, _TENSIONER_KEYS)
    arm_length = _num(t, "arm_length", "tensioner")
    vals = dict(
        pivot=_arr(_vec(t, "pivot", "tensioner")),
        arm_length=_arr(arm_length),
        pulley_radius=_arr(_num(t, "pulley_radius", "tensioner")),
        arm_mass=_arr(_num(t, "arm_mass", "tensioner")),
        arm_inertia=_arr(_num(t, "arm_inertia", "tensioner")),
        pulley_mass=_arr(_num(t, "pulley_mass", "tensioner")),
        pulley_inertia=_arr(_num(t, "pulley_inertia", "tensioner")),
        spring_stiffness=_arr(_num(t, "spring_stiffness", "tensioner")),
        spring_preload_deg=_arr(_num(t, "spring_preload_deg", "tensioner")),
        arm_angle_deg=_arr(_num(t, "arm_angle_deg", "tensioner", required=False)),
        damping=_arr(_num(t, "damping", "tensioner", required=False, default=0.0)),
    )
    cm = _num(t, "arm_cm_distance", "tensioner", required=False, default=0.0)
    if cm > arm_length:
        t.fail("arm_cm_distance", f"must not exceed arm_length = {arm_length!r}, got {cm!r}")
    vals["arm_cm_distance"] = _arr(cm)
    return Tensioner(**vals)


def _parse_route(data, names, has_tensioner, source) -> Route:
    t = _table(data, "route", source, _ROUTE_KEYS)
    order = t.strings("order")
    if len(order) < 2:
        t.fail("order", f"a belt needs at least two pulleys in its route, got {order!r}")
    known = set(names) | ({TENSIONER} if has_tensioner else set())
    for x in order:
        if x == TENSIONER and not has_tensioner:
            t.fail("order", f"{TENSIONER!r} is in the route but there is no [tensioner] table")
        if x not in known:
            t.fail("order", f"unknown pulley {x!r} (known: {', '.join(sorted(known))})")
    for x in names:
        if x not in order:
            t.fail("order", f"pulley {x!r} is not in the route")
    if has_tensioner and TENSIONER not in order:
        t.fail("order", f"a [tensioner] table is given but {TENSIONER!r} is not in the route")
    back = t.strings("back_side", required=False, default=[])
    for x in back:
        if x not in order:
            t.fail("back_side", f"{x!r} is not in route.order")
    direction = t.string("direction", required=False, default="cw", choices=DIRECTIONS)
    return Route(order=tuple(order), back_side=tuple(back), direction=direction)


def _parse_model(data, source) -> Model:
    t = _table(data, "model", source, _MODEL_KEYS)
    fidelity = t.string("fidelity", required=False, default="ancf", choices=FIDELITIES)
    n = t.integer("elements_per_span", required=False, default=16, minimum=1, maximum=MAX_ELEMENTS_PER_SPAN)
    effects = t.strings("effects", required=False, default=[])
    for e in effects:
        if e not in EFFECTS:
            t.fail("effects", f"unknown effect {e!r} (known: {', '.join(EFFECTS)})")
    bending = t.string("bending", required=False, default="linear", choices=BENDING_MODELS)
    return Model(fidelity=fidelity, elements_per_span=n, effects=tuple(effects), bending=bending)


def _window(t, group):
    t0 = _num(t, "t_start_s", group, required=False, default=0.0)
    t1 = _num(t, "t_end_s", group, required=False)
    if t1 is not None and t1 <= t0:
        t.fail("t_end_s", f"must be later than t_start_s = {t0!r}, got {t1!r}")
    return _arr(t0), _arr(t1)


def _parse_torques(data, free_names, source) -> tuple[Torque, ...]:
    if TENSIONER in free_names:
        free_names = [*free_names, ARM]
    if not isinstance(data, list):
        _fail("torque", f"expected an array of tables [[torque]], got {describe(data)}", source)
    out = []
    for i, d in enumerate(data):
        t = _table(d, f"torque[{i}]", source, _TORQUE_KEYS)
        name = t.string("pulley")
        if name not in free_names:
            t.fail(
                "pulley",
                f"{name!r} is not a free pulley of the route (free: {', '.join(free_names) or 'none'}; "
                "a driven pulley's motion is prescribed)",
            )
        t0, t1 = _window(t, "torque")
        out.append(
            Torque(
                pulley=name,
                mean_Nm=_arr(_num(t, "mean_Nm", "torque", required=False, default=0.0)),
                amplitude_Nm=_arr(_num(t, "amplitude_Nm", "torque", required=False, default=0.0)),
                frequency_hz=_arr(_num(t, "frequency_hz", "torque", required=False, default=0.0)),
                phase_deg=_arr(_num(t, "phase_deg", "torque", required=False, default=0.0)),
                t_start_s=t0,
                t_end_s=t1,
            )
        )
    return tuple(out)


def _parse_span_loads(data, spans, n_elements, fidelity, source) -> tuple[SpanLoad, ...]:
    if not isinstance(data, list):
        _fail("span_load", f"expected an array of tables [[span_load]], got {describe(data)}", source)
    out = []
    for i, d in enumerate(data):
        t = _table(d, f"span_load[{i}]", source, _SPAN_LOAD_KEYS)
        if fidelity != "ancf":
            t.fail("span", "a span load needs the hybrid model (model.fidelity = \"ancf\"): "
                   "the rotational model has no span nodes")
        name = t.string("span")
        if name not in spans:
            t.fail("span", f"unknown span {name!r} (spans: {', '.join(spans)})")
        node = t.integer("node")
        if not 1 <= node <= n_elements - 1:
            t.fail("node", f"must be an interior node, 1 to {n_elements - 1} (elements_per_span - 1), got {node!r}")
        t0, t1 = _window(t, "span_load")
        out.append(
            SpanLoad(
                span=name,
                node=node,
                amplitude_N=_arr(_num(t, "amplitude_N", "span_load")),
                frequency_hz=_arr(_num(t, "frequency_hz", "span_load")),
                phase_deg=_arr(_num(t, "phase_deg", "span_load", required=False, default=0.0)),
                t_start_s=t0,
                t_end_s=t1,
            )
        )
    return tuple(out)


def _parse_initial(data, free_names, has_tensioner, source) -> Initial:
    t = _table(data, "initial", source, _INITIAL_KEYS)
    rot = t.raw("rotation_deg", False) or {}
    if not isinstance(rot, dict):
        t.fail("rotation_deg", f"expected a table of pulley = angle (deg), got {describe(rot)}")
    pairs = []
    for name, v in rot.items():
        if name not in free_names:
            _fail(
                f"initial.rotation_deg.{name}",
                f"not a free pulley of the route (free: {', '.join(free_names) or 'none'})",
                source,
            )
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            _fail(f"initial.rotation_deg.{name}", f"expected a finite number (deg), got {describe(v)}", source)
        msg = schema.problem(schema.FIELDS["initial.rotation_deg"], v)
        if msg:
            _fail(f"initial.rotation_deg.{name}", msg, source)
        pairs.append((name, float(v)))
    arm = _num(t, "arm_angle_deg", "initial", required=False)
    if arm is not None and not has_tensioner:
        t.fail("arm_angle_deg", "there is no [tensioner]")
    return Initial(rotation_deg=tuple(pairs), arm_angle_deg=arm)


def _parse_simulation(data, spans, n_elements, fidelity, source) -> Simulation:
    t = _table(data, "simulation", source, _SIMULATION_KEYS)
    solver = t.string("solver", required=False, default=None, choices=SOLVERS)
    dt = _num(t, "dt_s", "simulation", required=False)
    rho = _num(t, "rho_inf", "simulation", required=False, default=0.9)
    rtol = _num(t, "rtol", "simulation", required=False, default=1e-6)
    atol = _num(t, "atol", "simulation", required=False, default=1e-9)
    out_dt = _num(t, "output_dt_s", "simulation", required=False)
    nodes = t.strings("nodes", required=False)
    if nodes is not None:
        if fidelity != "ancf" and nodes:
            t.fail("nodes", "node outputs need the hybrid model (model.fidelity = \"ancf\")")
        for x in nodes:
            name, _, k = x.rpartition(":")
            if name not in spans or not k.isdigit() or not 0 <= int(k) <= n_elements:
                t.fail("nodes", f"{x!r} is not \"<span>:<node>\" with a span of {', '.join(spans)} "
                       f"and a node 0 to {n_elements}")
        nodes = tuple(nodes)
    max_steps = t.integer("max_steps", required=False, default=1_000_000, minimum=1)
    return Simulation(solver=solver, dt_s=dt, rho_inf=rho, rtol=rtol, atol=atol, output_dt_s=out_dt,
                      nodes=nodes, max_steps=max_steps)


def _check_effects(scene: Scene, source: str):
    """A parameter of an effect that is not switched on is an error, not silently ignored."""
    model = scene.model
    if float(scene.belt.CA) > 0 and not model.has("belt_damping"):
        _fail("belt.CA", "given but \"belt_damping\" is not in model.effects", source)
    if scene.tensioner is not None and float(scene.tensioner.damping) > 0 and not model.has("tensioner_damping"):
        _fail("tensioner.damping", "given but \"tensioner_damping\" is not in model.effects", source)
    for i, p in enumerate(scene.pulleys):
        if float(p.bearing_damping) > 0 and not model.has("bearing_damping"):
            _fail(f"pulley[{i}].bearing_damping", "given but \"bearing_damping\" is not in model.effects", source)
        if float(jnp.linalg.norm(p.cm_offset)) > 0 and not model.has("unbalance"):
            _fail(f"pulley[{i}].cm_offset", "given but \"unbalance\" is not in model.effects", source)
        if float(p.fluctuation_amplitude_deg) > 0 and not model.has("speed_fluctuation"):
            _fail(
                f"pulley[{i}].fluctuation_amplitude_deg",
                "given but \"speed_fluctuation\" is not in model.effects",
                source,
            )


def _key_for(route_idx, scene_names, order):
    """Key path of a route entry for geometry errors."""
    name = order[route_idx]
    if name == TENSIONER:
        return "tensioner"
    return f"pulley[{scene_names.index(name)}].center"


def _check_geometry(scene: Scene, source: str):
    order = scene.route.order
    names = [p.name for p in scene.pulleys]
    if scene.tensioner is not None and scene.tensioner.arm_angle_deg is None:
        # the arm angle is not known yet: check the fixed pulleys against each other
        fixed = [i for i, n in enumerate(order) if n != TENSIONER]
        for a in range(len(fixed)):
            for b in range(a + 1, len(fixed)):
                pa, pb = scene.pulley(order[fixed[a]]), scene.pulley(order[fixed[b]])
                D = float(jnp.linalg.norm(pa.center - pb.center))
                if D <= float(pa.radius + pb.radius):
                    _fail(
                        _key_for(fixed[b], names, order),
                        f"pulleys {pa.name!r} and {pb.name!r} overlap: centre distance {D:.6g} m "
                        f"<= R1 + R2 = {float(pa.radius + pb.radius):.6g} m",
                        source,
                    )
        return None
    try:
        g = scene.geometry()
    except geometry.GeometryError as e:
        if e.kind in ("overlap", "tangent", "radius"):
            involved = [i for i in e.pulleys if order[i] == TENSIONER]
            if involved:
                key = "tensioner.arm_angle_deg"
            else:
                key = _key_for(max(e.pulleys, key=lambda i: names.index(order[i])), names, order)
        else:
            key = "route.order"
        _fail(key, str(e), source)
    return g


def parse_scene(data: dict[str, Any], source: str = "<dict>") -> Scene:
    """Validate a scene given as a dict (the parsed TOML) and build a :class:`Scene`.

    source: a label kept on the scene and on errors (e.g. the file path).
    Raises :class:`SceneError` (one line, starting with the key path).
    """
    top = _table(data, "", source, _TOP_KEYS)
    description = top.string("description", required=False, default="")
    if "belt" not in data:
        _fail("belt", "missing (required table [belt])", source)
    belt = _parse_belt(data["belt"], source)
    if "pulley" not in data:
        _fail("pulley", "missing (give the pulleys as [[pulley]] tables)", source)
    raw = data["pulley"]
    if not isinstance(raw, list):
        _fail("pulley", f"expected an array of tables [[pulley]], got {describe(raw)}", source)
    if not raw:
        _fail("pulley", "at least one [[pulley]] is required", source)
    pulleys = tuple(_parse_pulley(p, i, source) for i, p in enumerate(raw))
    seen: dict[str, int] = {}
    for i, p in enumerate(pulleys):
        if p.name in seen:
            _fail(f"pulley[{i}].name", f"duplicated name {p.name!r} (also pulley[{seen[p.name]}])", source)
        seen[p.name] = i
    drive = next((i for i, p in enumerate(pulleys) if p.driven), 0)
    for i, p in enumerate(raw):
        if i != drive and isinstance(p, dict) and "speed_rpm" in p:
            _fail(
                f"pulley[{i}].speed_rpm",
                f"only the drive pulley takes a speed: a driven pulley (driven = true), else the first "
                f"pulley (here pulley[{drive}], {pulleys[drive].name!r})",
                source,
            )
    tensioner = _parse_tensioner(data["tensioner"], source) if "tensioner" in data else None
    if "route" not in data:
        _fail("route", "missing (required table [route] with order = [...])", source)
    route = _parse_route(data["route"], [p.name for p in pulleys], tensioner is not None, source)
    model = _parse_model(data.get("model", {}), source)
    order = route.order
    spans = route.span_names
    free_names = [n for n in order if n == TENSIONER or not next(p for p in pulleys if p.name == n).driven]
    N = model.elements_per_span
    torques = _parse_torques(data["torque"], free_names, source) if "torque" in data else ()
    span_loads = (
        _parse_span_loads(data["span_load"], spans, N, model.fidelity, source) if "span_load" in data else ()
    )
    initial = _parse_initial(data.get("initial", {}), free_names, tensioner is not None, source)
    simulation = _parse_simulation(data.get("simulation", {}), spans, N, model.fidelity, source)
    scene = Scene(
        belt=belt,
        pulleys=pulleys,
        tensioner=tensioner,
        route=route,
        model=model,
        source=source,
        description=description,
        torques=torques,
        span_loads=span_loads,
        initial=initial,
        simulation=simulation,
    )
    _check_effects(scene, source)
    g = _check_geometry(scene, source)
    if g is not None and tensioner is None and belt.length is not None:
        path = float(g.length)
        if float(belt.length) >= path:
            _fail(
                "belt.length",
                f"{float(belt.length)!r} m is not shorter than the belt path {path:.6g} m "
                "between fixed pulleys: the belt would be slack",
                source,
            )
    from beltjax import validate  # (imports this module)

    problem = validate.scene_problem(scene)
    if problem is not None:
        _fail(*problem, source)
    return scene


def load_scene(path: str | os.PathLike) -> Scene:
    """Read and validate a TOML scene file; returns a :class:`Scene`.

    Raises :class:`SceneError` (one line) for a missing file, one that is not a regular file
    (a pipe, a device, a directory) or larger than the limit, text that is not UTF-8 (a
    byte-order mark is accepted), malformed TOML (with the line and column), values no key can
    carry (see :mod:`beltjax.textfile`) or an invalid scene.
    """
    p = os.fspath(path)
    data = textfile.load_toml(p, "scene", functools.partial(_fail, source=p))
    return parse_scene(data, source=p)


def loads_scene(text: str, source: str = "<string>") -> Scene:
    """Parse and validate a scene given as TOML text (see :func:`load_scene`)."""
    data = textfile.loads_toml(text, source, functools.partial(_fail, source=source))
    return parse_scene(data, source=source)
