"""The optimisation file: its dataclasses (:class:`Problem` and parts) and their parsing against a scene."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from beltjax import drive, friction, parameters, schema, textfile, tomltable
from beltjax.errors import BeltjaxError
from beltjax.schema import Field
from beltjax.scene import MAX_ELEMENTS_PER_SPAN, Scene, require_scene
from beltjax.tomltable import describe

#: most starts of one run (``starts``); the candidates for starts after the first: see beltjax.optimize.solver
MAX_STARTS = 16
#: temperature (Hz) of the log-sum-exp maximum over the sampled speeds
SOFT_HZ = 0.5
OBJECTIVES = ("resonance_band", "hub_load", "arm_motion")
CONSTRAINTS = ("min_wrap_deg", "static_tension", "arm_angle_deg", "no_overlap", "min_slip_margin")
#: penalty unit and default tolerance of each constraint kind (its own units)
_UNIT = {"min_wrap_deg": 1.0, "static_tension": 10.0, "arm_angle_deg": 1.0, "no_overlap": 1e-3, "min_slip_margin": 0.02}
_TOLERANCE = {"min_wrap_deg": 0.5, "static_tension": 2.0, "arm_angle_deg": 0.2, "no_overlap": 2e-4,
              "min_slip_margin": 0.005}
_UNIT_NAME = {"min_wrap_deg": "deg", "static_tension": "N", "arm_angle_deg": "deg", "no_overlap": "m",
              "min_slip_margin": "-"}
_TOP_KEYS = ("steps", "learning_rate", "tolerance", "patience", "min_steps", "starts", "elements_per_span",
             "description", "variable", "objective", "constraint")
_VARIABLE_KEYS = ("parameter", "lower", "upper", "scale")
_OBJECTIVE_KEYS = {
    "resonance_band": ("kind", "orders", "rpm", "modes", "margin_hz", "tolerance_hz", "speeds", "weight"),
    "hub_load": ("kind", "pulley", "weight"),
    "arm_motion": ("kind", "rpm", "speeds", "settle_s", "weight"),
}
_CONSTRAINT_KEYS = {
    "min_wrap_deg": ("kind", "value", "pulley", "weight", "tolerance"),
    "static_tension": ("kind", "min", "max", "span", "weight", "tolerance"),
    "arm_angle_deg": ("kind", "min", "max", "weight", "tolerance"),
    "no_overlap": ("kind", "clearance", "weight", "tolerance"),
    "min_slip_margin": ("kind", "value", "pulley", "weight", "tolerance"),
}


class OptimizeError(BeltjaxError):
    """A bad optimisation file or an impossible start: one line naming the key (``key``)."""


#: most optimiser steps (steps, patience, min_steps)
MAX_STEPS = 100_000
_STEPS_WHY = "a day of steps at 1 s each; a start stalls long before"
_HZ = schema.FIELDS["span_load.frequency_hz"]  # [0, 1e6] Hz: far above any belt-drive excitation
_TENSION = Field("N", 0.0, schema.FIELDS["span.tension"].high, "a span tension: beyond a conveyor's 1e7 N", ">=0")
#: accepted range of each number of the optimisation file (beltjax.schema's Field: unit, range,
#: reason); a drive speed (rpm) is in that of ``drive.rpm``, an order in that of ``fluctuation.order``,
#: a tension window in that of ``span.tension``, an arm-angle window in that of ``tensioner.arm_angle_deg``
RANGES: dict[str, Field] = {
    "steps": Field("", 1, MAX_STEPS, _STEPS_WHY),
    "patience": Field("", 1, MAX_STEPS, _STEPS_WHY),
    "min_steps": Field("", 0, MAX_STEPS, _STEPS_WHY),
    "learning_rate": Field("", 1e-6, 10.0, "Adam's step in units of each variable's scale: smaller, 1e5 steps "
                           "move a variable by less than a tenth of its scale; larger, every step leaps past the "
                           "bounds", ">0"),
    "tolerance": Field("", 0.0, 1.0, "relative to the smoothed loss: 1 is all of it", ">=0"),
    "scale": Field("x (upper - lower)", 1e-6, 1e3, "a typical change: from a millionth of the bounds' width, "
                   "which Adam's steps cannot cross, to a thousand times it, every step a leap past the bounds",
                   ">0"),
    "weight": Field("", 0.0, 1e6, "a term's relative weight (objectives 1, constraints 100 by default): a "
                    "million already decides the loss alone", ">=0"),
    "margin_hz": _HZ,
    "tolerance_hz": _HZ,
    "clearance": Field("m", 0.0, 1e2, "a gap between rims as wide as the largest drum (100 m)", ">=0"),
}
#: the range of a constraint's ``tolerance`` (its own units) by kind
_TOLERANCE_RANGE = {
    "min_wrap_deg": Field("deg", 0.0, 360.0, "a wrap angle lies in (0, 360) deg", ">=0"),
    "static_tension": _TENSION,
    "arm_angle_deg": Field("deg", 0.0, 3600.0, "ten turns", ">=0"),
    "no_overlap": RANGES["clearance"],
    "min_slip_margin": Field("-", 0.0, 2.0, "the margin asked for lies in (-1, 1)", ">=0"),
}
#: the range of a constraint's ``min`` and ``max`` by kind
_WINDOW_RANGE = {"static_tension": _TENSION, "arm_angle_deg": schema.FIELDS["tensioner.arm_angle_deg"]}


def _in(t: tomltable.Table, k: str, f: Field, v):
    """``v``, read at key ``k`` of table ``t`` (or its default), if it is None or in the range of
    ``f``; else ``t.fail`` naming the key with the range and its reason (:func:`beltjax.schema.problem`)."""
    msg = None if v is None else schema.problem(f, v)
    if msg:
        t.fail(k, msg)
    return v


# --------------------------------------------------------------------------- the problem


@dataclass(frozen=True)
class Variable:
    """A parameter to move: path (file units), bounds lower < upper, scale (typical change)."""

    path: str
    lower: float
    upper: float
    scale: float


@dataclass(frozen=True)
class Objective:
    """One objective term.  resonance_band: orders, rpm = (lo, hi) of the drive pulley (rpm),
    modes ("span", "all" or a number of lowest flexible modes), margin_hz (Hz), tolerance_hz
    (Hz: the shift still needed that counts as clear), speeds (samples in the band); hub_load:
    pulley (a route entry); arm_motion: rpm, speeds, settle_s (s: the transient before the
    periodic steady state, :mod:`beltjax.orders`), response (its settings: the scene's cycle and
    excited orders, :func:`beltjax.orders.for_scene`).  weight >= 0."""

    kind: str
    weight: float = 1.0
    orders: tuple[float, ...] = ()
    rpm: tuple[float, float] = (0.0, 0.0)
    modes: str | int = "span"
    margin_hz: float = 2.0
    tolerance_hz: float = 0.05
    speeds: int = 9
    pulley: str = ""
    settle_s: float = 1.0
    response: object = None  # arm_motion: the scene's beltjax.orders.Settings (static)


@dataclass(frozen=True)
class Constraint:
    """One penalised constraint: kind, bounds lower/upper (its units; None: none), pulley or
    span it is restricted to (None: all), penalty weight and report tolerance."""

    kind: str
    lower: float | None
    upper: float | None
    weight: float
    tolerance: float
    where: str | None = None


@dataclass(frozen=True)
class Problem:
    """A parsed optimisation file (see the module docstring); hashable, so compiled
    functions are shared between problems that are equal."""

    variables: tuple[Variable, ...]
    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...] = ()
    steps: int = 150
    learning_rate: float = 0.01
    tolerance: float = 1e-4
    patience: int = 30
    elements_per_span: int | None = None
    description: str = ""
    min_steps: int = 40
    starts: int = 3

    @property
    def paths(self) -> list[str]:
        """Parameter paths of the variables, in order."""
        return [v.path for v in self.variables]

    @property
    def scales(self) -> np.ndarray:
        """Scale of each variable (file units)."""
        return np.array([v.scale for v in self.variables])


def _raise(path: str, msg: str):
    raise OptimizeError(msg, path)


#: the optimisation file's reader: OptimizeError, its own wording of a few messages
_READ = tomltable.Reader(_raise, tomltable.Style(unknown_where=False, finite=True, choose=True, top="file"))


def _parse_variable(d, i: int, scene: Scene) -> Variable:
    key = f"variable[{i}]"
    t = _READ.table(d, key, _VARIABLE_KEYS)
    path = t.string("parameter", required=True)
    try:
        parameters.check(scene, path)
    except parameters.ParameterError as exc:
        raise OptimizeError(exc.quoted(path), f"{key}.parameter") from None
    lo = t.number("lower", required=True)
    hi = t.number("upper", required=True)
    for k, x in (("lower", lo), ("upper", hi)):
        try:  # a bound outside the parameter's accepted range (beltjax.schema)
            parameters.check_value(path, x)
        except parameters.ParameterError as exc:
            t.fail(k, f"{path} {str(exc)[len(path) + 2:]}")
    if not lo < hi:
        t.fail("upper", f"must be > lower = {lo!r}, got {hi!r}")
    scale = t.number("scale", required=False, default=hi - lo, positive=True)
    f = RANGES["scale"]
    if t.has("scale") and not f.low <= scale / (hi - lo) <= f.high:
        t.fail("scale", f"must lie in [{f.low:g}, {f.high:g}] x (upper - lower) = [{f.low * (hi - lo):g}, "
               f"{f.high * (hi - lo):g}] ({f.why}), got {scale!r}")
    x0 = float(parameters.get_value(scene, path))
    if not math.isfinite(x0):
        t.fail("parameter", f"{path} is not given in the scene (it is solved for); "
               "optimise the belt key the scene gives")
    if not lo <= x0 <= hi:
        t.fail("parameter", f"the scene's value {x0:.6g} of {path} lies outside [lower, upper] = [{lo:g}, {hi:g}]")
    return Variable(path, lo, hi, scale)


def _route_entry(t: tomltable.Table, k: str, scene: Scene, required: bool) -> str | None:
    name = t.string(k, required=required)
    if name is not None and name not in scene.route.order:
        t.fail(k, f"unknown pulley {name!r}; route entries: {', '.join(scene.route.order)}")
    return name


def _kind(d, key: str, choices) -> str:
    """The ``kind`` of an objective or constraint table (checked before its other keys)."""
    if not isinstance(d, dict):
        raise OptimizeError(f"expected a table, got {describe(d)}", key)
    only = {k: d[k] for k in ("kind",) if k in d}
    return _READ.table(only, key, ("kind",)).string("kind", required=True, choices=choices)


def _parse_objective(d, i: int, scene: Scene) -> Objective:
    key = f"objective[{i}]"
    kind = _kind(d, key, OBJECTIVES)
    t = _READ.table(d, key, _OBJECTIVE_KEYS[kind])
    weight = _in(t, "weight", RANGES["weight"], t.number("weight", required=False, default=1.0, nonnegative=True))
    if kind == "hub_load":
        return Objective(kind, weight, pulley=_route_entry(t, "pulley", scene, True))
    if kind == "arm_motion":
        return _arm_motion(t, d, scene, weight)
    orders = d.get("orders")
    if (not isinstance(orders, list) or not orders
            or any(isinstance(k, bool) or not isinstance(k, (int, float)) or not 0 < k < math.inf for k in orders)):
        got = (describe(orders) if not isinstance(orders, list) else repr(orders)) if orders is not None else "nothing"
        t.fail("orders", f"expected a non-empty array of positive finite numbers, got {got}")
    for j, k in enumerate(orders):  # multiples of the drive pulley's speed, as a scene's fluctuation orders
        _in(t, f"orders[{j}]", schema.FIELDS["fluctuation.order"], k)
    rpm = _band_rpm(t, d)
    modes = d.get("modes", "span")
    if isinstance(modes, bool) or not (modes in ("span", "all") or (isinstance(modes, int) and modes >= 1)):
        t.fail("modes", f"expected \"span\", \"all\" or a number of lowest modes >= 1, got {describe(modes)}")
    return Objective(
        kind, weight, orders=tuple(float(k) for k in orders), rpm=(float(rpm[0]), float(rpm[1])), modes=modes,
        margin_hz=_in(t, "margin_hz", RANGES["margin_hz"],
                      t.number("margin_hz", required=False, default=2.0, nonnegative=True)),
        tolerance_hz=_in(t, "tolerance_hz", RANGES["tolerance_hz"],
                         t.number("tolerance_hz", required=False, default=0.05, nonnegative=True)),
        speeds=t.integer("speeds", required=False, default=9, minimum=2, maximum=64),
    )


def _band_rpm(t, d) -> list:
    """The objective's rpm = [lower, upper] (drive-pulley speeds, rpm, 0 <= lower < upper, each in
    the range of ``drive.rpm``)."""
    rpm = d.get("rpm")
    if (not isinstance(rpm, list) or len(rpm) != 2
            or any(isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) for r in rpm)):
        got = describe(rpm) if rpm is not None else "nothing"
        t.fail("rpm", f"expected [lower, upper] speeds of the drive pulley (rpm), got {got}")
    if not 0 <= rpm[0] < rpm[1]:
        t.fail("rpm", f"need 0 <= lower < upper, got {rpm!r}")
    for j, r in enumerate(rpm):
        _in(t, f"rpm[{j}]", schema.FIELDS["drive.rpm"], r)
    return rpm


def _arm_motion(t, d, scene: Scene, weight: float) -> Objective:
    """An arm_motion objective: the tensioner arm's largest peak-to-peak (deg) in the periodic
    steady state over a speed band (the scene must have one: :func:`beltjax.orders.check`)."""
    from beltjax.orders import OrdersError, Settings, check, for_scene
    from beltjax.orders.run import check_batched, settle_problem

    rpm = _band_rpm(t, d)
    if rpm[0] <= 0:
        t.fail("rpm", f"need 0 < lower: the steady state needs a turning crank, got {rpm!r}")
    if scene.tensioner is None:
        t.fail("kind", "arm_motion needs a [tensioner]")
    try:
        check(scene, rpm)
        check_batched(scene, "arm_motion")
    except OrdersError as exc:
        t.fail("kind", f"arm_motion needs a periodic steady state: {exc}")
    settle_s = t.number("settle_s", required=False, default=1.0, nonnegative=True)
    if settle_problem(settle_s):  # beltjax orders' --settle-s range
        t.fail("settle_s", settle_problem(settle_s))
    return Objective("arm_motion", weight, rpm=(float(rpm[0]), float(rpm[1])),
                     speeds=t.integer("speeds", required=False, default=5, minimum=1, maximum=64),
                     settle_s=settle_s, response=for_scene(scene, Settings(samples=64, max_order=4.0)))


def _parse_constraint(d, i: int, scene: Scene) -> Constraint:
    key = f"constraint[{i}]"
    kind = _kind(d, key, CONSTRAINTS)
    t = _READ.table(d, key, _CONSTRAINT_KEYS[kind])
    weight = _in(t, "weight", RANGES["weight"], t.number("weight", required=False, default=100.0, nonnegative=True))
    tol = _in(t, "tolerance", _TOLERANCE_RANGE[kind],
              t.number("tolerance", required=False, default=_TOLERANCE[kind], nonnegative=True))
    if kind == "min_wrap_deg":
        value = t.number("value", required=True)
        if not 0 < value < 360:
            t.fail("value", f"must lie in (0, 360) deg, got {value!r}")
        return Constraint(kind, value, None, weight, tol, _route_entry(t, "pulley", scene, False))
    if kind == "no_overlap":
        clearance = t.number("clearance", required=False, default=0.0, nonnegative=True)
        return Constraint(kind, _in(t, "clearance", RANGES["clearance"], clearance), None, weight, tol)
    if kind == "min_slip_margin":
        value = t.number("value", required=False, default=0.0)
        if not -1 < value < 1:
            t.fail("value", f"a slip margin 1 - mu_needed / mu' lies in (-inf, 1]: ask for one in (-1, 1), got {value!r}")
        where = _route_entry(t, "pulley", scene, False)
        given = [scene.route.order[i] for i in friction.given(scene)]
        if not given:
            t.fail("kind", "the scene gives no friction coefficient (belt.friction_coefficient or a pulley's)")
        if where is not None and where not in given:
            t.fail("pulley", f"{where!r} has no friction coefficient in the scene")
        return Constraint(kind, value, None, weight, tol, where)
    if kind == "arm_angle_deg" and scene.tensioner is None:
        t.fail("kind", "the scene has no tensioner")
    lo, hi = (_in(t, k, _WINDOW_RANGE[kind], t.number(k, required=False)) for k in ("min", "max"))
    if lo is None and hi is None:
        t.fail("min", "give min, max or both")
    if lo is not None and hi is not None and not lo < hi:
        t.fail("max", f"must be > min = {lo!r}, got {hi!r}")
    span = None
    if kind == "static_tension":
        span = t.string("span", required=False)
        if span is not None and span not in scene.route.span_names:
            t.fail("span", f"unknown span {span!r}; spans: {', '.join(scene.route.span_names)}")
    return Constraint(kind, lo, hi, weight, tol, span)


def parse(spec: dict, scene: Scene) -> Problem:
    """Validate an optimisation file given as a dict (parsed TOML) against ``scene``.

    Raises :class:`OptimizeError` (one line naming the key) for unknown keys or kinds, bad
    bounds, a parameter path the scene lacks, a start outside the bounds, no variables or
    no objectives, steps < 1 and the like.
    """
    require_scene(scene)
    t = _READ.table(spec, "", _TOP_KEYS)
    variables = tuple(_parse_variable(d, i, scene) for i, d in enumerate(t.tables("variable")))
    if not variables:
        raise OptimizeError("at least one [[variable]] is required", "variable")
    seen = [v.path for v in variables]
    for i, p in enumerate(seen):
        if p in seen[:i]:
            raise OptimizeError(f"{p} is listed twice", f"variable[{i}].parameter")
    objectives = tuple(_parse_objective(d, i, scene) for i, d in enumerate(t.tables("objective")))
    if not objectives:
        raise OptimizeError("at least one [[objective]] is required", "objective")
    if all(o.weight == 0 for o in objectives):
        raise OptimizeError("every objective's weight is 0: nothing to minimise (give one a weight > 0)",
                            "objective[0].weight")
    constraints = tuple(_parse_constraint(d, i, scene) for i, d in enumerate(t.tables("constraint")))
    return Problem(
        variables=variables,
        objectives=objectives,
        constraints=constraints,
        steps=_in(t, "steps", RANGES["steps"], t.integer("steps", required=False, default=150, minimum=1)),
        learning_rate=_in(t, "learning_rate", RANGES["learning_rate"],
                          t.number("learning_rate", required=False, default=0.01, positive=True)),
        tolerance=_in(t, "tolerance", RANGES["tolerance"],
                      t.number("tolerance", required=False, default=1e-4, nonnegative=True)),
        patience=_in(t, "patience", RANGES["patience"], t.integer("patience", required=False, default=30, minimum=1)),
        elements_per_span=t.integer("elements_per_span", required=False, minimum=1, maximum=MAX_ELEMENTS_PER_SPAN),
        description=t.string("description", required=False, default=""),
        min_steps=_in(t, "min_steps", RANGES["min_steps"],
                      t.integer("min_steps", required=False, default=40, minimum=0)),
        starts=t.integer("starts", required=False, default=3, minimum=1, maximum=MAX_STARTS),
    )


def load(path, scene: Scene) -> Problem:
    """Read and validate an optimisation file (TOML, read by :mod:`beltjax.textfile`: a regular
    file of bounded size); :class:`OptimizeError` names the file or key."""
    spec = textfile.load_toml(textfile.file_name(path, "optimisation", textfile.keyed(_raise)), "optimisation",
                              textfile.keyed(_raise))
    return parse(spec, scene)


def working_scene(scene: Scene, problem: Problem) -> Scene:
    """The scene the optimisation runs on: canonical, with ``problem.elements_per_span`` if set."""
    sc = drive.canonical(scene)
    if problem.elements_per_span is not None and problem.elements_per_span != sc.model.elements_per_span:
        sc = dataclasses.replace(sc, model=dataclasses.replace(sc.model, elements_per_span=problem.elements_per_span))
    return sc


def band_rpm(objective: Objective) -> np.ndarray:
    """Sampled speeds (rpm) of a resonance objective's band, ends included."""
    return np.linspace(objective.rpm[0], objective.rpm[1], objective.speeds)


def _bands(problem: Problem) -> list[Objective]:
    return [o for o in problem.objectives if o.kind == "resonance_band"]


def sample_rpm(problem: Problem) -> np.ndarray:
    """Every resonance objective's sampled speeds (rpm), concatenated in objective order."""
    parts = [band_rpm(o) for o in _bands(problem)]
    return np.concatenate(parts) if parts else np.zeros(0)


def _band_starts(problem: Problem) -> list[int]:
    """Index of each resonance objective's first sampled speed in :func:`sample_rpm`."""
    return [int(k) for k in np.cumsum([0] + [o.speeds for o in _bands(problem)])[:-1]]


def _pairs(n: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(n) for j in range(i + 1, n)]
