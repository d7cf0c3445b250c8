"""The sweep file: its schema, parsing and checks, and the case table it makes (grid and random axes)."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from beltjax import drive, parameters, schema, statics, textfile, tomltable, validate
from beltjax.errors import BeltjaxError
from beltjax.scene import Scene, require_scene
from beltjax.tomltable import describe


#: most cases in one sweep
MAX_CASES = 100_000

#: most (case, speed) points in one sweep with the campbell output
MAX_CAMPBELL_POINTS = 1_000_000

#: most speeds in a campbell output
MAX_SPEEDS = 2000

#: (case, speed) points per compiled batch of a campbell output (bounds memory)
CAMPBELL_CHUNK_POINTS = 256

OUTPUTS = ("statics", "modal", "campbell", "response")

DISTRIBUTIONS = ("normal", "uniform")

SPACINGS = ("linear", "log")

#: case status codes (index = the integer code) and their meaning
STATUS = ("ok", "unstable", "invalid_value", "belt_slack", "belt_overstretched", "no_arm_balance",
          "not_converged", "span_slack", "non_finite", "supercritical", "overlap", "no_belt_path",
          "ill_conditioned", "transient_failed", "not_settled", "decoupler_overrun", "arm_wound", "span_overstretched")

REASONS = {
    "ok": "solved",
    "unstable": "the linearised drive has modes that grow: no natural frequencies (statics kept)",
    "invalid_value": "a parameter value outside its accepted range (beltjax.schema; e.g. a negative stiffness, "
                     "EI = 1e20, a centre-of-mass offset outside its pulley)",
    "overlap": "two pulleys overlap, or the belt has no tangent from one pulley to the next",
    "no_belt_path": "a degenerate wrap angle, a span through a pulley, or two spans crossing",
    "ill_conditioned": "beyond what float64 carries (a pinched span beside long ones, EA swamping the string "
                       "stiffness, EI swamping EA, a drive far from the origin)",
    "belt_slack": "belt too long to fit: it would hang slack",
    "belt_overstretched": f"belt too short to fit: more than {100 * statics.MAX_INSTALL_STRAIN:g} % stretch",
    "no_arm_balance": "no tensioner arm angle balances the spring against the belt",
    "not_converged": "no static equilibrium found (Newton, also with speed stepping)",
    "span_slack": "a span would go slack (tension <= 0)",
    "arm_wound": f"the mean loads would turn the tensioner arm more than {math.degrees(statics.MAX_ARM_SWING):g} deg "
                 "from its installed angle (wound round: they overpower the belt)",
    "span_overstretched": f"the mean loads would stretch a span beyond {100 * statics.MAX_INSTALL_STRAIN:g} % (they "
                          "overpower the belt)",
    "decoupler_overrun": "a decoupled pulley's mean load drives its rotor ahead: the clutch overruns, no steady state",
    "non_finite": "non-finite outputs",
    "transient_failed": "the response's transient (Dopri8) did not reach the end of its cycle",
    "not_settled": "the response had not settled into its periodic steady state after settle_s "
                   "(beltjax.orders.SETTLE_TOL)",
    "supercritical": "past the critical belt speed: a span's force on the pulleys (tension less rhoA c^2 lam) <= 0",
}

_CODE = {s: i for i, s in enumerate(STATUS)}

_TOP_KEYS = ("description", "outputs", "modes", "rpm", "settle_s", "chunk", "samples", "seed", "dask_scheduler", "grid",
             "random")

_GRID_KEYS = ("parameter", "values", "start", "stop", "num", "spacing")

_RANDOM_KEYS = ("parameter", "distribution", "mean", "nominal", "std", "low", "high", "tolerance",
                "relative_tolerance", "samples", "seed")

class SweepError(BeltjaxError):
    """A bad sweep file or request: one line starting with the key (``key`` attribute)."""


@dataclasses.dataclass(frozen=True)
class GridAxis:
    """A full-factorial axis: ``parameter`` path and its ``values`` (file units)."""

    parameter: str
    values: np.ndarray
    key: str = "grid"
    values_key: str = "grid"

@dataclasses.dataclass(frozen=True)
class RandomAxis:
    """A random parameter: ``distribution`` ("normal" | "uniform") and its spread (see the module doc).

    center: mean (None: the scene's nominal value); std / low, high / tolerance /
    relative_tolerance: exactly one spread (low and high together); seed: stream seed.
    """

    parameter: str
    distribution: str
    center: float | None
    std: float | None = None
    low: float | None = None
    high: float | None = None
    tolerance: float | None = None
    relative_tolerance: float | None = None
    seed: int = 0
    key: str = "random"

@dataclasses.dataclass(frozen=True)
class Spec:
    """A parsed sweep file (see the module docstring); ``rpm`` (rpm) is None without campbell."""

    outputs: tuple[str, ...] = ("statics", "modal")
    modes: int = 12
    rpm: np.ndarray | None = None
    grid: tuple[GridAxis, ...] = ()
    random: tuple[RandomAxis, ...] = ()
    samples: int = 0
    chunk: int | None = None
    dask_scheduler: str | None = None
    settle_s: float = 1.0
    description: str = ""
    source: str = "<dict>"
    raw: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)

    @property
    def parameters(self) -> list[str]:
        """Swept parameter paths: grid axes, then random ones."""
        return [a.parameter for a in self.grid] + [a.parameter for a in self.random]

    @property
    def grid_shape(self) -> tuple[int, ...]:
        return tuple(len(a.values) for a in self.grid)

    @property
    def n_cases(self) -> int:
        return int(np.prod(self.grid_shape, dtype=np.int64)) * (self.samples if self.random else 1)

def _raise(key: str, msg: str):
    raise SweepError(msg, key)

#: the sweep file's reader (SweepError; the scene file's wording)
_READ = tomltable.Reader(_raise)

def _rpm_range(key: str, v) -> np.ndarray:
    if not isinstance(v, list) or len(v) != 3:
        raise SweepError(f"expected [A, B, STEP] (three numbers, rpm), got {describe(v)}", key)
    a, b, step = (_READ.number(f"{key}[{i}]", x) for i, x in enumerate(v))
    msg = schema.problem(schema.FIELDS["drive.rpm"], b)
    if msg:
        raise SweepError(msg, f"{key}[1]")
    try:
        return validate.rpm_range(a, b, step, MAX_SPEEDS)
    except validate.RangeError as exc:
        raise SweepError(str(exc), key if exc.part is None else f"{key}[{exc.part}]") from None

def _parse_grid(i: int, d: dict) -> GridAxis:
    key = f"grid[{i}]"
    t = _READ.table(d, key, _GRID_KEYS)
    if "parameter" not in d:
        raise SweepError("missing (a parameter path such as \"belt.EI\")", f"{key}.parameter")
    path = t.string("parameter", nonempty=True)
    spacing = t.string("spacing", required=False, default="linear", choices=SPACINGS, nonempty=True)
    has_values = "values" in d
    has_range = [k for k in ("start", "stop", "num") if k in d]
    if has_values and has_range:
        raise SweepError("give either values or start/stop/num, not both", f"{key}.{has_range[0]}")
    if has_values:
        if "spacing" in d:
            raise SweepError("applies to start/stop/num only", f"{key}.spacing")
        v = d["values"]
        if not isinstance(v, list) or not v:
            raise SweepError(f"expected a non-empty array of numbers, got {describe(v)}", f"{key}.values")
        values = np.array([_READ.number(f"{key}.values[{j}]", x) for j, x in enumerate(v)])
    else:
        for k in ("start", "stop", "num"):
            if k not in d:
                raise SweepError("missing (give values = [...] or start, stop and num)", f"{key}.{k}")
        a, b = t.number("start"), t.number("stop")
        num = t.integer("num", minimum=1)
        if num > MAX_CASES:
            raise SweepError(f"at most {MAX_CASES} cases in a sweep, got {num}", f"{key}.num")
        if num == 1 and a != b:
            raise SweepError(f"1 gives start = {a!r} alone, never stop = {b!r}: give num >= 2, or values = [{a!r}]",
                             f"{key}.num")
        if spacing == "log":
            if a <= 0 or b <= 0:
                raise SweepError(f"\"log\" needs start and stop > 0, got {a!r}, {b!r}", f"{key}.spacing")
            values = np.geomspace(a, b, num)
        else:
            values = np.linspace(a, b, num)
    return GridAxis(parameter=path, values=values, key=key,
                    values_key=f"{key}.values" if has_values else f"{key}.start")

def _parse_random(i: int, d: dict, default_seed: int) -> tuple[RandomAxis, int | None]:
    key = f"random[{i}]"
    t = _READ.table(d, key, _RANDOM_KEYS)
    if "parameter" not in d:
        raise SweepError("missing (a parameter path such as \"belt.EI\")", f"{key}.parameter")
    path = t.string("parameter", nonempty=True)
    if "distribution" not in d:
        raise SweepError(f"missing (one of {', '.join(DISTRIBUTIONS)})", f"{key}.distribution")
    dist = t.string("distribution", choices=DISTRIBUTIONS, nonempty=True)
    nominal = t.boolean("nominal")
    if nominal and "mean" in d:
        raise SweepError("give either mean or nominal = true, not both", f"{key}.mean")
    mean = t.number("mean", required=False)
    spreads = [k for k in ("std", "tolerance", "relative_tolerance") if k in d]
    bounds = [k for k in ("low", "high") if k in d]
    if bounds:
        if dist != "uniform":
            raise SweepError("low/high bound a uniform distribution (distribution = \"uniform\")", f"{key}.{bounds[0]}")
        if len(bounds) == 1:
            other = "high" if bounds[0] == "low" else "low"
            raise SweepError("missing (low and high go together)", f"{key}.{other}")
        if spreads:
            raise SweepError("give either low/high or one spread, not both", f"{key}.{spreads[0]}")
        if nominal or mean is not None:
            raise SweepError("low/high give the interval: no centre (mean or nominal) with them", f"{key}.{'mean' if mean is not None else 'nominal'}")
        low, high = t.number("low"), t.number("high")
        if not high > low:
            raise SweepError(f"must be > low = {low!r}, got {high!r}", f"{key}.high")
        axis = RandomAxis(path, dist, None, low=low, high=high, key=key)
    else:
        if not spreads:
            need = "std, tolerance or relative_tolerance" if dist == "normal" else "low/high, tolerance or relative_tolerance"
            raise SweepError(f"no spread: give {need}", key)
        if len(spreads) > 1:
            raise SweepError(f"give only one spread (also {spreads[0]})", f"{key}.{spreads[1]}")
        s = spreads[0]
        if s == "std" and dist != "normal":
            raise SweepError("std belongs to a normal distribution (uniform: low/high or tolerance)", f"{key}.std")
        if mean is None and not nominal:
            raise SweepError("missing: give mean = value or nominal = true (the scene's value)", f"{key}.mean")
        x = t.number(s, positive=True)  # 0 would draw the centre in every case: a grid value
        if s == "relative_tolerance" and x >= 1.0:
            raise SweepError(f"must be < 1 (a fraction: 0.003 is 0.3 %), got {d[s]!r}", f"{key}.relative_tolerance")
        axis = RandomAxis(path, dist, mean, **{s: x}, key=key)
    seed = t.integer("seed", required=False, default=default_seed, minimum=0)
    samples = t.integer("samples", required=False, minimum=1)
    return dataclasses.replace(axis, seed=seed), samples

def parse_spec(data: Mapping[str, Any], source: str = "<dict>") -> Spec:
    """Validate a sweep given as a dict (the parsed TOML); raises :class:`SweepError` naming the key.

    Checks the structure only; :func:`check_spec` checks it against a scene.
    """
    top = _READ.table(data, "", _TOP_KEYS)
    description = top.string("description", required=False, default="", nonempty=True)
    outs = data.get("outputs", ["statics", "modal"])
    if not isinstance(outs, list) or not outs:
        raise SweepError(f"expected a non-empty array of {', '.join(OUTPUTS)}, got {describe(outs)}", "outputs")
    outputs = []
    for j, o in enumerate(outs):
        o = _READ.string(f"outputs[{j}]", o, choices=OUTPUTS, nonempty=True)
        if o in outputs:
            raise SweepError(f"{o!r} listed twice", f"outputs[{j}]")
        outputs.append(o)
    outputs = tuple(o for o in OUTPUTS if o in outputs)
    modes = top.integer("modes", required=False, default=12, minimum=1)
    rpm = None
    if "campbell" in outputs:
        if "rpm" not in data:
            raise SweepError("missing: the campbell output needs rpm = [A, B, STEP] (drive-pulley speeds, rpm)", "rpm")
        rpm = _rpm_range("rpm", data["rpm"])
    elif "rpm" in data:
        raise SweepError("given but \"campbell\" is not in outputs", "rpm")
    settle_s = top.number("settle_s", required=False, default=1.0, nonnegative=True)
    from beltjax.orders.run import settle_problem

    problem = settle_problem(settle_s)
    if problem:
        raise SweepError(problem, "settle_s")
    if "settle_s" in data and "response" not in outputs:
        raise SweepError("given but \"response\" is not in outputs", "settle_s")
    chunk = top.integer("chunk", required=False, minimum=1)
    seed = top.integer("seed", required=False, default=0, minimum=0)
    sched = top.string("dask_scheduler", required=False, nonempty=True)
    grid = tuple(_parse_grid(i, d) for i, d in enumerate(top.tables("grid")))
    rnd, counts = [], []
    for i, d in enumerate(top.tables("random")):
        a, n = _parse_random(i, d, seed)
        rnd.append(a)
        counts.append((f"random[{i}].samples", n))
    if not grid and not rnd:
        raise SweepError("no sweep axes: give at least one [[grid]] or [[random]] table", "grid")
    samples = top.integer("samples", required=False, minimum=1)
    skey = "samples"
    for k, n in counts:
        if n is None:
            continue
        if samples is not None and n != samples:
            raise SweepError(f"{n} differs from {samples} ({skey}): random parameters are drawn jointly, "
                                "so every [[random]] table has the same samples", k)
        samples, skey = n, k
    if rnd and samples is None:
        raise SweepError("missing: give samples = N (top level or in a [[random]] table)", "samples")
    if not rnd and samples is not None:
        raise SweepError("given but there is no [[random]] table", "samples")
    seen: dict[str, str] = {}
    for a in [*grid, *rnd]:
        if a.parameter in seen:
            raise SweepError(f"{a.parameter!r} is already swept by {seen[a.parameter]}", f"{a.key}.parameter")
        seen[a.parameter] = a.key
    if "belt.static_tension" in seen and "belt.length" in seen:
        raise SweepError("belt.length and belt.static_tension cannot both be swept: the belt is given by one of them", f"{seen['belt.length']}.parameter")
    spec = Spec(outputs=outputs, modes=modes, rpm=rpm, grid=grid, random=tuple(rnd), samples=samples or 0,
                chunk=chunk, dask_scheduler=sched, settle_s=settle_s, description=description, source=source,
                raw=dict(data))
    n = spec.n_cases
    if n > MAX_CASES:
        dims = " x ".join(str(x) for x in spec.grid_shape) + (f" x {spec.samples} samples" if rnd else "")
        raise SweepError(f"the sweep has {n} cases ({dims}), more than the limit {MAX_CASES}", skey if rnd else grid[-1].key)
    if rpm is not None and n * len(rpm) > MAX_CAMPBELL_POINTS:
        raise SweepError(f"{n} cases x {len(rpm)} speeds exceed the limit of {MAX_CAMPBELL_POINTS} campbell points", "rpm")
    return spec

def load_spec(path: str | os.PathLike) -> Spec:
    """Read and validate a sweep file (TOML, read by :mod:`beltjax.textfile`: a regular file of
    bounded size); raises :class:`SweepError` (one line)."""
    p = textfile.file_name(path, "sweep", textfile.keyed(_raise))
    data = textfile.load_toml(p, "sweep", textfile.keyed(_raise))
    return parse_spec(data, source=p)

def nominal_value(scene: Scene, path: str) -> float:
    """The scene's value at ``path`` (file units).  ``belt.length`` of a scene given by its
    tension (and ``belt.static_tension`` of one given by its length) is the installed one."""
    parameters.check(scene, path)
    if path in ("belt.length", "belt.static_tension") and getattr(scene.belt, path.split(".")[1]) is None:
        inst = statics.install_compiled(drive.canonical(scene))
        statics.check_installation(scene, inst)
        return float(inst.belt_length if path == "belt.length" else inst.tension)
    return float(parameters.get_value(scene, path))

def _check_range(key: str, path: str, values) -> None:
    """A value that no case could use (outside the range of :mod:`beltjax.schema`): one line."""
    try:
        parameters.check_value(path, values)
    except parameters.ParameterError as exc:
        raise SweepError(f"{path} {str(exc)[len(path) + 2:]}", key) from None

def _half_band(a: RandomAxis, center: float) -> tuple[str, float]:
    """(the spread's key, the half-width of its band about ``center``): tolerance; 3 std (the
    band a tolerance gives a normal distribution); relative_tolerance x |centre|."""
    if a.tolerance is not None:
        return "tolerance", a.tolerance
    if a.relative_tolerance is not None:
        return "relative_tolerance", abs(center) * a.relative_tolerance
    return "std", 3.0 * a.std

def _check_band(scene: Scene, a: RandomAxis) -> None:
    """A spread whose band, centre +- half (:func:`_half_band`), leaves the parameter's accepted
    range (:mod:`beltjax.schema`), as low/high outside it would, or is not finite: one line naming
    the spread's key.  Draws beyond the band (a normal's tails) are each a case's invalid_value."""
    center = a.center if a.center is not None else nominal_value(scene, a.parameter)
    k, half = _half_band(a, center)
    with np.errstate(over="ignore"):
        lo, hi = center - half, center + half
    f = schema.field(a.parameter)
    shown = {"tolerance": "tolerance", "std": "3 std", "relative_tolerance": "relative_tolerance x |centre|"}[k]
    band = f"the band {center:g} +- {shown} = [{lo:g}, {hi:g}]"
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise SweepError(f"{band} is not finite", f"{a.key}.{k}")
    if f is not None and (schema.problem(f, lo) or schema.problem(f, hi)):
        raise SweepError(f"{band} leaves the accepted range of {a.parameter}, {f.range_text()} ({f.why}): give a "
                         "smaller spread", f"{a.key}.{k}")

def check_spec(scene: Scene, spec: Spec) -> None:
    """Check a parsed sweep against ``scene``: parameter paths, value ranges and the random
    spreads' bands (:func:`_check_band`) (:class:`SweepError`)."""
    require_scene(scene)
    if not isinstance(spec, Spec):
        raise SweepError(f"expected a sweep (beltjax.load_sweep), got {type(spec).__name__}", "spec")
    for a in [*spec.grid, *spec.random]:
        try:
            parameters.check(scene, a.parameter)
        except parameters.ParameterError as exc:
            raise SweepError(exc.quoted(a.parameter), f"{a.key}.parameter") from None
    for a in spec.grid:
        _check_range(a.values_key, a.parameter, a.values)
    for a in spec.random:
        if a.low is not None:
            _check_range(f"{a.key}.low", a.parameter, [a.low, a.high])
            continue
        if a.center is not None:
            _check_range(f"{a.key}.mean", a.parameter, [a.center])
        _check_band(scene, a)

def _draw(axis: RandomAxis, center: float, n: int, index: int) -> np.ndarray:
    """``n`` draws of a random axis (file units) about ``center``."""
    rng = np.random.default_rng([axis.seed, index])
    if axis.low is not None:
        return rng.uniform(axis.low, axis.high, n)
    half = _half_band(axis, center)[1]
    # (check_spec keeps the band finite; a draw that is not is its case's invalid_value, never a warning)
    with np.errstate(all="ignore"):
        if axis.distribution == "uniform":
            return center + rng.uniform(-half, half, n)
        return center + (half / 3.0) * rng.standard_normal(n)

def cases(scene: Scene, spec: Spec) -> dict[str, np.ndarray]:
    """The case table: {parameter path: (n_cases,) values} (file units), grid axes full-factorial
    (first slowest), random samples fastest.  Deterministic (seeded)."""
    check_spec(scene, spec)
    shape = spec.grid_shape
    n_grid = int(np.prod(shape, dtype=np.int64))
    reps = spec.samples if spec.random else 1
    out: dict[str, np.ndarray] = {}
    if spec.grid:
        mesh = np.meshgrid(*[a.values for a in spec.grid], indexing="ij")
        for a, m in zip(spec.grid, mesh):
            out[a.parameter] = np.repeat(m.reshape(-1), reps)
    for i, a in enumerate(spec.random):
        center = a.center if a.center is not None else (None if a.low is not None else nominal_value(scene, a.parameter))
        out[a.parameter] = np.tile(_draw(a, center, reps, i), n_grid)
    return out

def _precheck(scene: Scene, values: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """(n,) status codes of the scene file's checks on every case (:func:`beltjax.validate.case_status`,
    vectorised over the cases; 0 where they pass)."""
    status, _ = validate.case_status(scene, values, n)
    return np.asarray([_CODE[s] for s in status], dtype=int) if n else np.zeros(0, int)
