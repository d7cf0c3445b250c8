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
from beltjax.scene import Scene
from beltjax.tomltable import describe


#: most cases in one sweep
MAX_CASES = 100_000

#: most (case, speed) points in one sweep with the campbell output
MAX_CAMPBELL_POINTS = 1_000_000

#: most speeds in a campbell output
MAX_SPEEDS = 2000

#: (case, speed) points per compiled batch of a campbell output (bounds memory)
CAMPBELL_CHUNK_POINTS = 256

OUTPUTS = ("statics", "modal", "campbell")

DISTRIBUTIONS = ("normal", "uniform")

SPACINGS = ("linear", "log")

#: case status codes (index = the integer code) and their meaning
STATUS = ("ok", "unstable", "invalid_value", "belt_slack", "belt_overstretched", "no_arm_balance",
          "not_converged", "span_slack", "non_finite", "supercritical", "overlap", "no_belt_path",
          "ill_conditioned")

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
    "non_finite": "non-finite outputs",
    "supercritical": "past the critical belt speed: a span's force on the pulleys (tension less rhoA c^2 lam) <= 0",
}

_CODE = {s: i for i, s in enumerate(STATUS)}

_TOP_KEYS = ("description", "outputs", "modes", "rpm", "chunk", "samples", "seed", "dask_scheduler", "grid", "random")

_GRID_KEYS = ("parameter", "values", "start", "stop", "num", "spacing")

_RANDOM_KEYS = ("parameter", "distribution", "mean", "nominal", "std", "low", "high", "tolerance",
                "relative_tolerance", "samples", "seed")

class SweepError(BeltjaxError):
    """A bad sweep file or request: one line starting with the key (``key`` attribute)."""

    def __init__(self, key: str, message: str):
        super().__init__(message, key)

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
    raise SweepError(key, msg)

#: the sweep file's reader (SweepError; the scene file's wording)
_READ = tomltable.Reader(_raise)

def _rpm_range(key: str, v) -> np.ndarray:
    if not isinstance(v, list) or len(v) != 3:
        raise SweepError(key, f"expected [A, B, STEP] (three numbers, rpm), got {describe(v)}")
    a, b, step = (_READ.number(f"{key}[{i}]", x) for i, x in enumerate(v))
    if step <= 0:
        raise SweepError(f"{key}[2]", f"STEP must be > 0, got {v[2]!r}")
    if a < 0:
        raise SweepError(f"{key}[0]", f"start A must be >= 0, got {v[0]!r}")
    if b < a:
        raise SweepError(f"{key}[1]", f"end B must be >= start A, got {v[1]!r}")
    msg = schema.problem(schema.FIELDS["drive.rpm"], b)
    if msg:
        raise SweepError(f"{key}[1]", msg)
    n = math.ceil((b + step / 2 - a) / step)
    if n > MAX_SPEEDS:
        raise SweepError(key, f"gives {n} speeds, at most {MAX_SPEEDS} allowed")
    return np.arange(a, b + step / 2, step)

def _parse_grid(i: int, d: dict) -> GridAxis:
    key = f"grid[{i}]"
    t = _READ.table(d, key, _GRID_KEYS)
    if "parameter" not in d:
        raise SweepError(f"{key}.parameter", "missing (a parameter path such as \"belt.EI\")")
    path = t.string("parameter", nonempty=True)
    spacing = t.string("spacing", required=False, default="linear", choices=SPACINGS, nonempty=True)
    has_values = "values" in d
    has_range = [k for k in ("start", "stop", "num") if k in d]
    if has_values and has_range:
        raise SweepError(f"{key}.{has_range[0]}", "give either values or start/stop/num, not both")
    if has_values:
        if "spacing" in d:
            raise SweepError(f"{key}.spacing", "applies to start/stop/num only")
        v = d["values"]
        if not isinstance(v, list) or not v:
            raise SweepError(f"{key}.values", f"expected a non-empty array of numbers, got {describe(v)}")
        values = np.array([_READ.number(f"{key}.values[{j}]", x) for j, x in enumerate(v)])
    else:
        for k in ("start", "stop", "num"):
            if k not in d:
                raise SweepError(f"{key}.{k}", "missing (give values = [...] or start, stop and num)")
        a, b = t.number("start"), t.number("stop")
        num = t.integer("num", minimum=1)
        if num > MAX_CASES:
            raise SweepError(f"{key}.num", f"at most {MAX_CASES} cases in a sweep, got {num}")
        if spacing == "log":
            if a <= 0 or b <= 0:
                raise SweepError(f"{key}.spacing", f"\"log\" needs start and stop > 0, got {a!r}, {b!r}")
            values = np.geomspace(a, b, num)
        else:
            values = np.linspace(a, b, num)
    return GridAxis(parameter=path, values=values, key=key,
                    values_key=f"{key}.values" if has_values else f"{key}.start")

def _parse_random(i: int, d: dict, default_seed: int) -> tuple[RandomAxis, int | None]:
    key = f"random[{i}]"
    t = _READ.table(d, key, _RANDOM_KEYS)
    if "parameter" not in d:
        raise SweepError(f"{key}.parameter", "missing (a parameter path such as \"belt.EI\")")
    path = t.string("parameter", nonempty=True)
    if "distribution" not in d:
        raise SweepError(f"{key}.distribution", f"missing (one of {', '.join(DISTRIBUTIONS)})")
    dist = t.string("distribution", choices=DISTRIBUTIONS, nonempty=True)
    nominal = t.boolean("nominal")
    if nominal and "mean" in d:
        raise SweepError(f"{key}.mean", "give either mean or nominal = true, not both")
    mean = t.number("mean", required=False)
    spreads = [k for k in ("std", "tolerance", "relative_tolerance") if k in d]
    bounds = [k for k in ("low", "high") if k in d]
    if bounds:
        if dist != "uniform":
            raise SweepError(f"{key}.{bounds[0]}", "low/high bound a uniform distribution (distribution = \"uniform\")")
        if len(bounds) == 1:
            other = "high" if bounds[0] == "low" else "low"
            raise SweepError(f"{key}.{other}", "missing (low and high go together)")
        if spreads:
            raise SweepError(f"{key}.{spreads[0]}", "give either low/high or one spread, not both")
        if nominal or mean is not None:
            raise SweepError(f"{key}.{'mean' if mean is not None else 'nominal'}",
                             "low/high give the interval: no centre (mean or nominal) with them")
        low, high = t.number("low"), t.number("high")
        if not high > low:
            raise SweepError(f"{key}.high", f"must be > low = {low!r}, got {high!r}")
        axis = RandomAxis(path, dist, None, low=low, high=high, key=key)
    else:
        if not spreads:
            need = "std, tolerance or relative_tolerance" if dist == "normal" else "low/high, tolerance or relative_tolerance"
            raise SweepError(key, f"no spread: give {need}")
        if len(spreads) > 1:
            raise SweepError(f"{key}.{spreads[1]}", f"give only one spread (also {spreads[0]})")
        s = spreads[0]
        if s == "std" and dist != "normal":
            raise SweepError(f"{key}.std", "std belongs to a normal distribution (uniform: low/high or tolerance)")
        if mean is None and not nominal:
            raise SweepError(f"{key}.mean", "missing: give mean = value or nominal = true (the scene's value)")
        x = t.number(s, nonnegative=True)
        if s == "relative_tolerance" and x >= 1.0:
            raise SweepError(f"{key}.relative_tolerance", f"must be < 1 (a fraction: 0.003 is 0.3 %), got {d[s]!r}")
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
        raise SweepError("outputs", f"expected a non-empty array of {', '.join(OUTPUTS)}, got {describe(outs)}")
    outputs = []
    for j, o in enumerate(outs):
        o = _READ.string(f"outputs[{j}]", o, choices=OUTPUTS, nonempty=True)
        if o in outputs:
            raise SweepError(f"outputs[{j}]", f"{o!r} listed twice")
        outputs.append(o)
    outputs = tuple(o for o in OUTPUTS if o in outputs)
    modes = top.integer("modes", required=False, default=12, minimum=1)
    rpm = None
    if "campbell" in outputs:
        if "rpm" not in data:
            raise SweepError("rpm", "missing: the campbell output needs rpm = [A, B, STEP] (drive-pulley speeds, rpm)")
        rpm = _rpm_range("rpm", data["rpm"])
    elif "rpm" in data:
        raise SweepError("rpm", "given but \"campbell\" is not in outputs")
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
        raise SweepError("grid", "no sweep axes: give at least one [[grid]] or [[random]] table")
    samples = top.integer("samples", required=False, minimum=1)
    skey = "samples"
    for k, n in counts:
        if n is None:
            continue
        if samples is not None and n != samples:
            raise SweepError(k, f"{n} differs from {samples} ({skey}): random parameters are drawn jointly, "
                                "so every [[random]] table has the same samples")
        samples, skey = n, k
    if rnd and samples is None:
        raise SweepError("samples", "missing: give samples = N (top level or in a [[random]] table)")
    if not rnd and samples is not None:
        raise SweepError("samples", "given but there is no [[random]] table")
    seen: dict[str, str] = {}
    for a in [*grid, *rnd]:
        if a.parameter in seen:
            raise SweepError(f"{a.key}.parameter", f"{a.parameter!r} is already swept by {seen[a.parameter]}")
        seen[a.parameter] = a.key
    if "belt.static_tension" in seen and "belt.length" in seen:
        raise SweepError(f"{seen['belt.length']}.parameter",
                         "belt.length and belt.static_tension cannot both be swept: the belt is given by one of them")
    spec = Spec(outputs=outputs, modes=modes, rpm=rpm, grid=grid, random=tuple(rnd), samples=samples or 0,
                chunk=chunk, dask_scheduler=sched, description=description, source=source, raw=dict(data))
    n = spec.n_cases
    if n > MAX_CASES:
        dims = " x ".join(str(x) for x in spec.grid_shape) + (f" x {spec.samples} samples" if rnd else "")
        raise SweepError(skey if rnd else grid[-1].key, f"the sweep has {n} cases ({dims}), more than the limit {MAX_CASES}")
    if rpm is not None and n * len(rpm) > MAX_CAMPBELL_POINTS:
        raise SweepError("rpm", f"{n} cases x {len(rpm)} speeds exceed the limit of {MAX_CAMPBELL_POINTS} campbell points")
    return spec

def load_spec(path: str | os.PathLike) -> Spec:
    """Read and validate a sweep file (TOML, read by :mod:`beltjax.textfile`: a regular file of
    bounded size); raises :class:`SweepError` (one line)."""
    p = os.fspath(path)
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
        raise SweepError(key, f"{path} {str(exc)[len(path) + 2:]}") from None

def check_spec(scene: Scene, spec: Spec) -> None:
    """Check a parsed sweep against ``scene``: parameter paths and value ranges (:class:`SweepError`)."""
    for a in [*spec.grid, *spec.random]:
        try:
            parameters.check(scene, a.parameter)
        except parameters.ParameterError as exc:
            raise SweepError(f"{a.key}.parameter", str(exc)) from None
    for a in spec.grid:
        _check_range(a.values_key, a.parameter, a.values)
    for a in spec.random:
        if a.low is not None:
            _check_range(f"{a.key}.low", a.parameter, [a.low, a.high])
        elif a.center is not None:
            _check_range(f"{a.key}.mean", a.parameter, [a.center])

def _draw(axis: RandomAxis, center: float, n: int, index: int) -> np.ndarray:
    """``n`` draws of a random axis (file units) about ``center``."""
    rng = np.random.default_rng([axis.seed, index])
    if axis.low is not None:
        return rng.uniform(axis.low, axis.high, n)
    if axis.tolerance is not None:
        half = axis.tolerance
    elif axis.relative_tolerance is not None:
        half = abs(center) * axis.relative_tolerance
    else:
        half = 3.0 * axis.std
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
