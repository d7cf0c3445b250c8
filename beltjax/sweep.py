"""Batched parametric sweeps: parameter grids, random samples and tolerance studies.

One compiled function evaluates a whole batch of scenes: ``jax.vmap`` of
``case_outputs(set_values(scene, values))`` over the cases, run in chunks of a fixed
size (the last chunk padded, so there is no recompilation).  The batch carries every
scalar parameter of the scene (:func:`full_values`), so every sweep of a scene, and of
any scene with the same structure (pulleys, mesh, effects, belt given by tension or by
length), shares one compilation.  Scale-out:

* several local accelerators (GPUs): each chunk is sharded over them (``shard_map`` on
  the case axis; not measured here, the machine has none).  Host CPU "devices" are used
  only when passed explicitly (``devices=``; see :func:`_devices` for why);
* ``backend="dask"``: the chunks are tasks on a ``dask.distributed`` cluster, each
  worker running the same compiled function (compiled once per worker process): the
  scheduler at the sweep file's ``dask_scheduler``, else at ``$BELTJAX_DASK_SCHEDULER``,
  else a LocalCluster of one single-threaded worker process per core.  Needs the extra
  ``pip install 'beltjax[dask]'``.

Library: :func:`load_spec` / :func:`parse_spec` (+ :func:`check_spec`) read a sweep,
:func:`cases` makes its case table ``{path: (n,) values}``, :func:`evaluate` runs any
case table, :func:`case_outputs` is the pure single-case function (jit, vmap, grad),
:func:`columns`, :func:`statistics` and :func:`failures` summarise, :func:`run` is
``beltjax sweep``.

Sweep file (TOML)
-----------------
::

    description = "two-pulley bench: tension x EI"   # optional
    outputs = ["statics", "modal"]    # any of "statics", "modal", "campbell" (default statics, modal)
    modes = 12                        # modes kept per case (default 12; rigid-body modes count)
    # rpm = [0, 2500, 50]             # campbell only: drive-pulley speeds A, B, STEP (rpm, B included)
    # chunk = 1                       # cases per compiled batch (default 1 per CPU device, 128 on GPUs)
    # samples = 200                   # random samples (or in each [[random]] table; all must agree)
    # seed = 0                        # default seed of the [[random]] tables
    # dask_scheduler = "tcp://host:8786"   # backend "dask": an existing scheduler

    [[grid]]                          # a full-factorial axis
    parameter = "belt.static_tension" # a beltjax.parameters path (file units)
    values = [200, 400, 600]          # or: start, stop, num (and spacing = "linear" | "log")

    [[random]]                        # a random parameter (all drawn jointly: `samples` cases)
    parameter = "pulley.alternator.center.x"
    distribution = "normal"           # "normal" or "uniform" (required)
    nominal = true                    # centre: the scene's value (or mean = 0.2232)
    tolerance = 0.0005                # spread; see below
    samples = 200
    seed = 0

Spread of a ``[[random]]`` table, exactly one of:

* ``std`` (normal only): standard deviation (parameter units);
* ``low`` and ``high`` (uniform only, no centre): the interval;
* ``tolerance``: an absolute band ``centre +- tolerance``; uniform draws fill the
  band, normal draws take it as +-3 standard deviations (std = tolerance / 3);
* ``relative_tolerance``: the same band as a fraction of the centre
  (``0.003`` is +-0.3 %).

The centre is ``mean``, or with ``nominal = true`` the scene's value.  The belt's
unstretched ``belt.length`` of a scene given by ``static_tension`` is the
installed length (:func:`beltjax.statics.install`), and vice versa; sweeping
``belt.length`` switches every case to length mode (the tension follows from the
installation), so a belt-length tolerance changes the tension as a real belt does.

Cases: the grid axes are full-factorial (the first axis varies slowest); the
random parameters are drawn jointly, each from its own stream seeded by
``(seed, table index)``.  A grid together with random tables is allowed: every
grid point gets the same ``samples`` draws (common random numbers, so grid
points differ by the grid values only); cases = grid points x samples, the
samples varying fastest.  A parameter may appear in only one axis, and
``belt.static_tension`` and ``belt.length`` not together.  At most
:data:`MAX_CASES` cases.

Outputs per case
----------------
statics
    span tensions per span (route order), hub force magnitudes per route entry,
    installation tension, unstretched belt length, the tensioner's arm angle and
    spring moment (tensioner drives), Newton convergence.  At the drive pulley's
    ``speed_rpm`` (steady motion), as ``beltjax statics``.
modal
    natural frequencies (Hz) of the nominal scene's lowest ``modes`` modes, followed
    into every case by their shapes, and a stability flag: column ``f<k>_hz`` is the
    nominal's k-th mode (its label in ``sweep.json``, ``nominal_modes``) in every row,
    wherever it sits in the case's own order, so a column keeps its mode where two
    modes cross (a transverse mode rising through a rotational one as the tension
    grows).  Each case's modes come from the compiled eigen-solve with their
    mass-weighted shapes (a few more modes than kept, so that a mode that moved up is
    still found) and are matched to the nominal's by MAC and an optimal assignment
    (:mod:`beltjax.mode_tracking`; a repeated pair as a subspace); ``mode_match`` is a
    case's lowest MAC (near 1: every column holds the nominal's mode; low: a mode has
    changed shape, e.g. two modes mixed near a veering; a column whose mode is not found
    is NaN and counts 0).  Tracking to the nominal rather than along a grid axis works for
    random (tolerance) studies too and needs no order of the cases.  Without modes of
    the nominal (its statics fail, or it is unstable) the columns are the lowest
    ``modes`` sorted per case, and ``sweep.json`` says so.
campbell
    the same modes' frequencies at each ``rpm`` speed per case: matched to the nominal's
    at the lowest speed, then followed along the case's speeds by their shapes (as
    ``beltjax campbell``); ``campbell_mode_match`` is a case's lowest MAC.

A case without an admissible state is never silently wrong: its outputs are NaN
and its ``status`` names the cause (:data:`STATUS`): before any computation, the
scene file's checks (:func:`beltjax.validate.case_status`, vectorised over the
cases) give ``invalid_value`` (a value outside the parameter's range of
:mod:`beltjax.schema`), ``overlap`` (pulleys overlap, or no tangent between
neighbours), ``no_belt_path`` (a degenerate wrap, a span through a pulley, spans
crossing) and ``ill_conditioned`` (a derived float64 limit); then a belt that cannot
be fitted (slack, over-stretched, no tensioner balance), statics not converged
(retried with speed stepping), a span gone slack, non-finite outputs, ``supercritical``
(the drive speed past the critical belt speed: a span's force on the pulleys <= 0,
:mod:`beltjax.critical`); ``unstable`` (modes that grow) keeps the statics and has NaN
frequencies.  The run summary counts them by cause.  A sweep accepts exactly what a scene
file accepts.

Command line: ``beltjax sweep SCENE SWEEP.toml [--backend local|dask] --out DIR``
writes ``sweep.csv`` (one row per case: case, parameters, outputs, status),
``sweep.json`` (spec, statistics of every output, failures, timing),
``sweep_campbell.csv`` (campbell output, one row per case and speed) and plots.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import math
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import (critical, drive, drive_modal, mode_tracking, parameters, schema, statics, sweep_modes, textfile,
                     tomltable, validate)
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


# --------------------------------------------------------------------------- the sweep file


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


# --------------------------------------------------------------------------- cases


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


# --------------------------------------------------------------------------- the batched function


@dataclasses.dataclass(frozen=True)
class _Options:
    """Static options of the compiled batch (hashable)."""

    outputs: tuple[str, ...]
    modes: int
    gyro: bool
    steps: int = 1
    track: int = 0


def case_outputs(scene: Scene, values: Mapping[str, Any], outputs: tuple[str, ...] = ("statics", "modal"),
                 modes: int = 12, rpm=None, gyroscopic: bool = False, steps: int = 1,
                 track: int = 0) -> dict[str, jax.Array]:
    """Outputs of one case: ``scene`` with ``values`` {path: scalar} set (pure JAX: jit, vmap, grad).

    outputs, modes, gyroscopic (solve the gyroscopic problem of the moving belt) and steps
    (speed steps of the statics) are static.  Returns the arrays of :func:`evaluate` for one
    case (no ``status``): an integer ``code`` (index into :data:`STATUS`) and, per output,
    span_tensions_N (N), hub_forces_N (N, magnitudes), installation_tension_N (N),
    belt_length_m (m), tensioner_angle_deg (deg), spring_moment_Nm (N m), converged;
    frequencies_hz (Hz, NaN when unstable), stable; campbell_hz (Hz, per ``rpm`` speed),
    campbell_stable.  The statics run at the drive pulley's speed_rpm (m/s of belt).  With
    ``track`` > 0 the lowest ``track`` modes come with their mass-whitened shapes for mode
    tracking (:func:`beltjax.drive_modal.tracking_shapes`): modal_W, modal_owner, campbell_W,
    campbell_owner (the frequencies are then the lowest ``track``, sorted).
    """
    sc = parameters.set_values(scene, values)
    inst = statics.install(sc)
    v = drive.belt_speed(sc)
    qi, inst, (conv, _, _) = statics.equilibrium(sc, inst, speed=v, steps=steps)
    out = statics.static_outputs(sc, qi, inst, v)
    lam = inst.stretch
    conds = [~jnp.isfinite(lam) | (lam <= 1.0), lam - 1.0 > statics.MAX_INSTALL_STRAIN]
    codes = [_CODE["belt_slack"], _CODE["belt_overstretched"]]
    if sc.tensioner is not None:
        conds.insert(0, ~jnp.isfinite(inst.arm_angle))
        codes.insert(0, _CODE["no_arm_balance"])
    conds += [conv < 0.5, ~jnp.all(out["tensions"] > 0), critical.supercritical(sc, qi, inst, v)]
    codes += [_CODE["not_converged"], _CODE["span_slack"], _CODE["supercritical"]]
    res: dict[str, jax.Array] = {}
    if "statics" in outputs:
        res["span_tensions_N"] = out["tensions"]
        res["hub_forces_N"] = jnp.linalg.norm(out["hubs"], axis=1)
        res["belt_length_m"] = inst.belt_length
        if sc.tensioner is not None:
            res["spring_moment_Nm"] = drive.spring_moment(out["theta"], sc)
        res["converged"] = conv > 0.5
    res["installation_tension_N"] = inst.tension  # evaluate checks each case's solved installation
    if sc.tensioner is not None:
        res["tensioner_angle_deg"] = jnp.rad2deg(out["theta"])
    nr = drive_modal.n_rigid_modes(sc)
    stable = jnp.asarray(True)
    if "modal" in outputs:
        if track:
            t = drive_modal.tracking_shapes(sc, qi, inst, v, track, gyroscopic, full=False)
            stable, f = t["stable"], t["freqs"]
            res["modal_W"], res["modal_owner"] = t["W"], t["owner"]
        else:
            M, G, K = drive_modal.linearise(qi, sc, inst, v)
            stable, f = drive_modal.frequencies_from_matrices(M, G, K, nr, gyroscopic, drive_modal.rigid_mode(sc, inst))
            f = f[:modes]
        res["frequencies_hz"] = jnp.where(stable, f, jnp.nan)
        res["stable"] = stable
    if "campbell" in outputs:
        transport = sc.model.has("transport")

        def at(r):
            vv = drive.belt_speed(sc, r)
            q2, inst2, info = statics.equilibrium(sc, inst, speed=vv, steps=4)
            if track:
                t = drive_modal.tracking_shapes(sc, q2, inst2, vv, track, transport, full=False)
                ok = t["stable"] & (info[0] > 0.5) & ~critical.supercritical(sc, q2, inst2, vv)
                return jnp.where(ok, t["freqs"], jnp.nan), ok, t["W"], t["owner"]
            M, G, K = drive_modal.linearise(q2, sc, inst2, vv)
            ok, f = drive_modal.frequencies_from_matrices(M, G, K, nr, transport, drive_modal.rigid_mode(sc, inst2))
            ok = ok & (info[0] > 0.5) & ~critical.supercritical(sc, q2, inst2, vv)
            return jnp.where(ok, f[:modes], jnp.nan), ok

        got = jax.vmap(at)(jnp.asarray(rpm, dtype=jnp.float64))
        res["campbell_hz"], res["campbell_stable"] = got[:2]
        if track:
            res["campbell_W"], res["campbell_owner"] = got[2:]
    skip = ("frequencies_hz", "campbell_hz", *sweep_modes.SHAPE_KEYS)
    finite = [jnp.all(jnp.isfinite(x)) for k, x in res.items() if k not in skip]
    conds += [~jnp.all(jnp.asarray([*finite, True])), ~stable]
    codes += [_CODE["non_finite"], _CODE["unstable"]]
    res["code"] = jnp.select(conds, [jnp.asarray(c) for c in codes], jnp.asarray(_CODE["ok"]))
    return res


def _case(scene: Scene, values: Mapping[str, jax.Array], rpm: jax.Array, opts: _Options) -> dict:
    return case_outputs(scene, values, opts.outputs, opts.modes, rpm, opts.gyro, opts.steps, opts.track)


def full_values(scene: Scene, values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` completed with the scene's value of every other scalar parameter
    (:func:`beltjax.parameters.paths`; the belt by the key the sweep or the scene uses).

    A batch over the complete set has one pytree structure for every sweep of a scene, so
    all sweeps of a scene (and of scenes of the same structure) share one compilation.
    """
    belt = scene.belt
    if "belt.length" in values or ("belt.static_tension" not in values and belt.length is not None):
        skip = "belt.static_tension"
    else:
        skip = "belt.length"
    out: dict[str, Any] = {}
    for p in parameters.paths(scene):
        if p == skip or p in values:
            continue
        try:
            x = parameters.get_value(scene, p)
        except parameters.ParameterError:
            continue
        if p in ("belt.length", "belt.static_tension") and getattr(belt, p.split(".")[1]) is None:
            continue  # not given: solved by the installation
        out[p] = float(x)
    out.update(values)
    return out


@functools.cache
def _batch_fn(opts: _Options, devices: tuple | None, keys: tuple[str, ...]) -> Callable:
    """The jitted batch ``(scene, X (B, len(keys)), rpm (S,)) -> outputs (B, ...)``, column j of X
    the values of parameter ``keys[j]``; sharded over ``devices`` (shard_map on the case axis)
    when given.  One per option set and parameter set, shared by all sweeps."""

    def batch(scene, X, rpm):
        return jax.vmap(lambda x: _case(scene, dict(zip(keys, x)), rpm, opts))(X)

    if devices is None:
        return jax.jit(batch)
    from jax.sharding import Mesh
    from jax.sharding import PartitionSpec as P

    mesh = Mesh(np.asarray(devices), ("cases",))
    return jax.jit(jax.shard_map(batch, mesh=mesh, in_specs=(P(), P("cases"), P()), out_specs=P("cases"),
                                 check_vma=False))


def _devices(devices="auto") -> tuple | None:
    """Devices to shard a batch over (None: no sharding).  "auto": every local device when there
    are several accelerators (GPU/TPU).  Several CPU "devices" (``--xla_force_host_platform_device_count``)
    share the same cores, and XLA's CPU runtime wedged here (all threads idle) running the batched
    eigen-solves on two of them, so CPU devices are used only when passed explicitly."""
    if devices is None:
        return None
    if isinstance(devices, str):
        if devices != "auto":
            raise SweepError("devices", f"\"auto\", None or a sequence of JAX devices, got {devices!r}")
        devs = jax.local_devices()
        return tuple(devs) if len(devs) > 1 and devs[0].platform != "cpu" else None
    devs = tuple(devices)
    return devs if len(devs) > 1 else None


def default_chunk(devices: tuple | None = None) -> int:
    """Default cases per compiled batch: 1 per CPU device, 128 on accelerators.

    On CPU a batch is slower per case than one case at a time: the batched arrays leave the
    cache (each fused operation streams over the whole batch) and batched LAPACK calls are
    loops; a vmapped Newton also iterates until its slowest case converges.  Two-pulley bench
    (130 coordinates), statics + modes, interleaved on the shared 2-core machine: 4.2-5.1 ms
    per case in batches of 1, 3.9-8.9 ms of 2, 6-11 ms of 4, 13-19 ms of 8 and 13-20 ms of 32,
    against 5.0-5.5 ms for the jitted single case (benchmarks/bench_sweep.py).  A batch pays
    on GPUs (128 there is a guess, not measured).
    """
    devs = devices or tuple(jax.local_devices()[:1])
    return len(devs) if devs[0].platform == "cpu" else 128 * len(devs)


def _chunk_size(n: int, chunk: int | None, n_rpm: int, devices: tuple | None) -> int:
    """Cases per compiled batch: ``chunk`` (fewer for campbell, to bound memory), at most the
    cases rounded up to 8 (few shapes), a multiple of the device count."""
    n_dev = len(devices) if devices else 1
    chunk = default_chunk(devices) if chunk is None else chunk
    size = chunk if n_rpm == 0 else max(1, min(chunk, CAMPBELL_CHUNK_POINTS // n_rpm))
    size = min(size, 8 * math.ceil(n / 8))
    return n_dev * math.ceil(size / n_dev)


def _matrix(values: Mapping[str, np.ndarray], keys: tuple[str, ...], size: int) -> np.ndarray:
    """(size, len(keys)) float64 values, the last case repeated to pad to ``size`` rows."""
    X = np.stack([np.asarray(values[k], dtype=float) for k in keys], axis=1)
    return np.concatenate([X, np.repeat(X[-1:], size - len(X), axis=0)]) if len(X) < size else X


def _run_chunk(scene: Scene, values: Mapping[str, np.ndarray], rpm: np.ndarray, opts: _Options,
               size: int, devices: tuple | None) -> dict[str, np.ndarray]:
    """One chunk (<= size cases), padded to ``size``; cases whose statics did not converge are
    run again with speed stepping (8 steps), as :func:`beltjax.statics.analyse_statics` does."""
    keys = tuple(sorted(values))
    X = _matrix(values, keys, size)
    n = len(next(iter(values.values())))
    out = {k: np.array(np.asarray(a)[:n]) for k, a in _batch_fn(opts, devices, keys)(scene, X, rpm).items()}
    again = np.flatnonzero(out["code"] == _CODE["not_converged"])
    if again.size:
        fn8 = _batch_fn(dataclasses.replace(opts, steps=8), devices, keys)
        redo = fn8(scene, _matrix({k: np.asarray(values[k])[again] for k in keys}, keys, size), rpm)
        for k in out:
            out[k][again] = np.asarray(redo[k])[: again.size]
    return out


#: one JAX computation at a time per process: concurrent executions from several threads (a Dask
#: worker with threads, or several workers in one process) deadlocked XLA's CPU runtime here
_EXECUTION_LOCK = threading.Lock()


def _chunk_task(scene_np, values, rpm, opts: _Options, size: int, cache_dir: str | None):
    """A Dask task: one chunk on a worker (the scene travels with numpy leaves)."""
    with _EXECUTION_LOCK:
        if cache_dir and not jax.config.jax_compilation_cache_dir:
            try:
                jax.config.update("jax_compilation_cache_dir", cache_dir)
                jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
            except Exception:  # pragma: no cover - a worker without a writable cache
                pass
        scene = jax.tree.map(jnp.asarray, scene_np)
        return _run_chunk(scene, values, rpm, opts, size, None)


def _slices(n: int, size: int) -> list[slice]:
    return [slice(s, min(s + size, n)) for s in range(0, n, size)]


def _dask_client(address):
    """(client, owned) for ``address``: a dask.distributed Client, a scheduler address, or None for a
    LocalCluster with one single-threaded worker process per core."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise SweepError("backend", "the dask backend needs dask.distributed: pip install 'beltjax[dask]'") from None
    if address is not None and not isinstance(address, str):
        return address, False
    address = address or os.environ.get("BELTJAX_DASK_SCHEDULER") or None
    if address:
        try:
            return Client(address, timeout="20s"), True
        except OSError as exc:
            raise SweepError("dask_scheduler", f"cannot reach the Dask scheduler {address!r}: {exc}") from None
    cluster = LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    return Client(cluster), True


def _run_local(scene: Scene, chunks: list[dict], rpm: np.ndarray, opts: _Options, size: int,
               devices: tuple | None, progress, post=lambda r: r) -> list[dict]:
    """The chunks one after the other in this process (``post`` applied to each chunk's outputs)."""
    results, done, n = [], 0, sum(len(next(iter(c.values()))) for c in chunks)
    for c in chunks:
        results.append(post(_run_chunk(scene, c, rpm, opts, size, devices)))
        done += len(next(iter(c.values())))
        if progress is not None:
            progress(done, n)
    return results


def _run_dask(scene: Scene, chunks: list[dict], rpm: np.ndarray, opts: _Options, size: int, dask,
              progress, post=lambda r: r) -> list[dict]:
    """The chunks as tasks on a dask.distributed cluster (results in chunk order; ``post`` applied
    to each chunk's outputs as it arrives)."""
    from dask.distributed import as_completed

    client, owned = _dask_client(dask)
    n = sum(len(next(iter(c.values()))) for c in chunks)
    results: list = [None] * len(chunks)
    try:
        [sfut] = client.scatter([jax.tree.map(np.asarray, scene)], broadcast=True, hash=False)
        cache = jax.config.jax_compilation_cache_dir
        futs = [client.submit(_chunk_task, sfut, c, rpm, opts, size, cache, pure=False) for c in chunks]
        index = {f.key: i for i, f in enumerate(futs)}
        done = 0
        for fut in as_completed(futs):
            i = index[fut.key]
            results[i] = post(fut.result())
            done += len(next(iter(chunks[i].values())))
            if progress is not None:
                progress(done, n)
    finally:
        if owned:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None:
                cluster.close()
    return results


def evaluate(scene: Scene, values: Mapping[str, Any], outputs: tuple[str, ...] | list[str] = ("statics", "modal"),
             modes: int = 12, rpm=None, chunk: int | None = None, progress: Callable[[int, int], None] | None = None,
             backend: str = "local", dask=None, devices="auto", reference="auto") -> dict[str, np.ndarray]:
    """Evaluate a batch of cases with one compiled, vmapped function (in chunks).

    values: {parameter path: (n,) values} (file units, e.g. from :func:`cases`);
    outputs: subset of :data:`OUTPUTS`; modes: frequencies kept per case; rpm: (S,)
    drive-pulley speeds (rpm) of the campbell output; chunk: cases per compiled batch
    (the last one padded; default :func:`default_chunk`); progress: callable(done, total) after each chunk;
    backend: "local" (this process) or "dask" (chunks as tasks on a dask.distributed
    cluster; ``dask`` is a Client, a scheduler address, or None for the
    ``BELTJAX_DASK_SCHEDULER`` address or a LocalCluster of one process per core);
    devices (local backend): shard each chunk over these JAX devices (``shard_map`` on
    the case axis; the chunk is a multiple of their number); "auto" uses every local
    accelerator when there are several (see :func:`_devices` for CPU devices), None none;
    reference: the modes the frequency columns follow, :func:`beltjax.sweep_modes.references` ("auto": those of
    ``scene`` itself, the nominal; None: no tracking, the lowest ``modes`` sorted per case).

    Frequency columns follow modes, not ranks: column k of ``frequencies_hz`` is the nominal
    scene's k-th mode (ascending at the nominal), found in each case by its shape (the
    eigen-solve returns mass-whitened shapes of a few more modes than kept; each case's modes
    are matched to the nominal's by MAC and an optimal assignment, repeated pairs as
    subspaces: :func:`beltjax.sweep_modes.track_chunk`), so a mode keeps its column where modes cross; NaN where
    no mode of the case matches it.  ``campbell_hz`` follows them from the lowest speed along
    each case's speeds.  ``mode_labels`` / ``campbell_mode_labels`` name the columns (the
    nominal's labels, from its shapes).

    Returns numpy arrays with the case on axis 0: ``status`` (str, :data:`STATUS`),
    ``code`` (int); statics: ``span_tensions_N`` (n, spans), ``hub_forces_N`` (n,
    route entries; magnitudes), ``installation_tension_N``, ``belt_length_m``,
    ``tensioner_angle_deg`` and ``spring_moment_Nm`` (tensioner drives), ``converged``;
    modal: ``frequencies_hz`` (n, modes), ``mode_mac`` (n, modes: each column's MAC with the
    nominal's mode), ``stable``; campbell: ``campbell_rpm`` (S,), ``campbell_hz`` (n, S,
    modes), ``campbell_stable`` (n, S), ``campbell_mode_match`` (n,: the lowest MAC of a case's
    tracking); and the lists ``mode_labels``, ``campbell_mode_labels`` (None: not tracked).
    Failed cases are NaN in every output (unstable ones in the frequencies only).
    """
    outputs = [outputs] if isinstance(outputs, str) else list(outputs)
    bad = [o for o in outputs if o not in OUTPUTS]
    outputs = tuple(o for o in OUTPUTS if o in outputs)
    if bad or not outputs:
        raise SweepError("outputs", f"choose from {', '.join(OUTPUTS)}")
    if backend not in ("local", "dask"):
        raise SweepError("backend", f"must be \"local\" or \"dask\", got {backend!r}")
    values = {k: np.asarray(v, dtype=float).reshape(-1) for k, v in values.items()}
    if not values:
        raise SweepError("values", "no parameters given")
    lengths = {len(v) for v in values.values()}
    if len(lengths) != 1 or 0 in lengths:
        raise SweepError("values", f"every parameter needs the same, non-zero number of values, got {sorted(lengths)}")
    for k in values:
        try:
            parameters.check(scene, k)
        except parameters.ParameterError as exc:
            raise SweepError("values", str(exc)) from None
    n = lengths.pop()
    if n > MAX_CASES:
        raise SweepError("values", f"{n} cases, more than the limit {MAX_CASES}")
    scene = drive.canonical(scene)
    rpm = np.zeros(0) if "campbell" not in outputs else np.asarray(rpm, dtype=float).reshape(-1)
    if "campbell" in outputs and rpm.size == 0:
        raise SweepError("rpm", "the campbell output needs drive-pulley speeds (rpm)")
    modes = max(1, min(int(modes), drive.n_independent(scene)))
    dp = scene.route.order[drive.drive_pulley(scene)]
    moving = float(drive.belt_speed(scene)) != 0.0 or f"pulley.{dp}.speed_rpm" in values
    refs, track = {}, 0
    if reference is not None and ("modal" in outputs or "campbell" in outputs):
        refs = sweep_modes.references(scene, outputs, modes, rpm) if isinstance(reference, str) else dict(reference)
        track = mode_tracking.n_computed(modes, drive.n_independent(scene))
    opts = _Options(outputs=outputs, modes=modes, gyro=scene.model.has("transport") and moving, track=track)
    post = functools.partial(sweep_modes.track_chunk, refs=refs, modes=modes) if track else (lambda r: r)
    pre = _precheck(scene, values, n)
    invalid = pre != _CODE["ok"]
    if invalid.all():
        run_values = values
    else:  # evaluate a valid case in place of invalid ones (their outputs are discarded)
        j = int(np.argmin(invalid))
        run_values = {k: np.where(invalid, v[j], v) for k, v in values.items()}
    run_values = {k: np.broadcast_to(np.asarray(v, float), (n,)) for k, v in full_values(scene, run_values).items()}
    devices = _devices(devices) if backend == "local" else None
    size = _chunk_size(n, chunk, rpm.size, devices)
    chunks = [{k: v[sl] for k, v in run_values.items()} for sl in _slices(n, size)]
    if backend == "local":
        results = _run_local(scene, chunks, rpm, opts, size, devices, progress, post)
    else:
        results = _run_dask(scene, chunks, rpm, opts, size, dask, progress, post)
    out = {k: np.concatenate([r[k] for r in results]) for k in results[0]}
    # the checks that need each case's solved installation: the idler where its arm settles, the
    # string-spread limit at the installed tension (validate.solved_status)
    arm = out["tensioner_angle_deg"] if scene.tensioner is not None else None
    solved, _ = validate.solved_status(scene, out["installation_tension_N"], arm, values, n)
    solved_ok = (pre == _CODE["ok"]) & np.isin(out["code"], (_CODE["ok"], _CODE["unstable"]))
    pre = np.where(solved_ok, [_CODE[s] for s in solved], pre)
    if "statics" not in outputs:
        out.pop("installation_tension_N")
        out.pop("tensioner_angle_deg", None)
    out = _finish(out, pre, rpm)
    for key, o in (("mode_labels", "modal"), ("campbell_mode_labels", "campbell")):
        if o in outputs:
            out[key] = list(refs[o][1]) if refs.get(o) else None
    return out


def _finish(out: dict[str, np.ndarray], pre: np.ndarray, rpm: np.ndarray) -> dict[str, np.ndarray]:
    """Status strings; NaN in every output of a failed case (frequencies only for unstable ones).
    pre: (n,) codes of the checks before the computation (0: passed)."""
    code = np.where(pre != _CODE["ok"], pre, out.pop("code")).astype(int)
    failed = (code != _CODE["ok"]) & (code != _CODE["unstable"])
    for k, v in out.items():
        if v.dtype.kind == "f":
            v[failed] = np.nan
        elif k in ("converged", "stable", "campbell_stable"):
            v[failed] = False
    if "frequencies_hz" in out:
        out["frequencies_hz"][code == _CODE["unstable"]] = np.nan
    if rpm.size:
        out["campbell_rpm"] = rpm
    out["code"] = code
    out["status"] = np.asarray(STATUS, dtype=object)[code]
    return out


# --------------------------------------------------------------------------- tables and statistics


def columns(scene: Scene, result: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-case output columns of :func:`evaluate`'s result, tidy: ``tension_<span>_N``,
    ``hub_<entry>_N``, ``installation_tension_N``, ``belt_length_m``, ``tensioner_angle_deg``,
    ``spring_moment_Nm``, ``converged``, ``f<k>_hz`` (the nominal scene's k-th mode, followed
    by its shape: see :func:`evaluate`), ``mode_match`` (the lowest MAC of a case's columns
    with the nominal's modes, 0 where one is not found), ``stable``,
    ``campbell_unstable_from_rpm``, ``campbell_mode_match``."""
    cols: dict[str, np.ndarray] = {}
    if "span_tensions_N" in result:
        for j, name in enumerate(drive.span_names(scene)):
            cols[f"tension_{name}_N"] = result["span_tensions_N"][:, j]
        for j, name in enumerate(scene.route.order):
            cols[f"hub_{name}_N"] = result["hub_forces_N"][:, j]
        for k in ("installation_tension_N", "belt_length_m", "tensioner_angle_deg", "spring_moment_Nm", "converged"):
            if k in result:
                cols[k] = result[k]
    if "frequencies_hz" in result:
        for m in range(result["frequencies_hz"].shape[1]):
            cols[f"f{m + 1}_hz"] = result["frequencies_hz"][:, m]
        if "mode_mac" in result:
            mac = result["mode_mac"]
            cols["mode_match"] = np.where(np.isfinite(mac).any(axis=1),
                                          np.min(np.where(np.isfinite(mac), mac, 0.0), axis=1), np.nan)
        cols["stable"] = result["stable"]
    if "campbell_hz" in result:
        rpm = result["campbell_rpm"]
        bad = ~result["campbell_stable"]
        first = np.where(bad.any(axis=1), rpm[np.argmax(bad, axis=1)], np.nan)
        cols["campbell_unstable_from_rpm"] = np.where(result["code"] == _CODE["ok"], first, np.nan)
        if "campbell_mode_match" in result:
            cols["campbell_mode_match"] = result["campbell_mode_match"]
    return cols


def statistics(x) -> dict[str, float | int | None]:
    """mean, std, min, max, p5, p50, p95 and count of the finite values of ``x``."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return dict(count=0, mean=None, std=None, min=None, max=None, p5=None, p50=None, p95=None)
    p = np.percentile(x, [5, 50, 95])
    return dict(count=int(x.size), mean=float(x.mean()), std=float(x.std(ddof=1)) if x.size > 1 else 0.0,
                min=float(x.min()), max=float(x.max()), p5=float(p[0]), p50=float(p[1]), p95=float(p[2]))


def failures(result: Mapping[str, np.ndarray], max_cases: int = 20) -> dict:
    """{status: {count, reason, cases (first indices)}} of every case that is not "ok"."""
    out = {}
    for s in STATUS[1:]:
        idx = np.flatnonzero(result["status"] == s)
        if idx.size:
            out[s] = dict(count=int(idx.size), reason=REASONS[s], cases=[int(i) for i in idx[:max_cases]])
    return out


def _fmt(x) -> str:
    if isinstance(x, (bool, np.bool_)):
        return "1" if x else "0"
    if isinstance(x, str):
        return x
    x = float(x)
    return "nan" if not math.isfinite(x) else repr(x)


def write_csv(path: Path, values: Mapping[str, np.ndarray], cols: Mapping[str, np.ndarray], status) -> None:
    """sweep.csv: case, parameter columns (paths), output columns, status."""
    n = len(status)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", *values, *cols, "status"])
        for i in range(n):
            w.writerow([i, *(_fmt(v[i]) for v in values.values()), *(_fmt(c[i]) for c in cols.values()), status[i]])


def write_campbell_csv(path: Path, result: Mapping[str, np.ndarray]) -> None:
    """sweep_campbell.csv: one row per case and speed: case, rpm, f<k>_hz, stable."""
    F, ok, rpm = result["campbell_hz"], result["campbell_stable"], result["campbell_rpm"]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", "rpm", *(f"f{m + 1}_hz" for m in range(F.shape[2])), "stable"])
        for i in range(F.shape[0]):
            for j, r in enumerate(rpm):
                w.writerow([i, _fmt(r), *(_fmt(x) for x in F[i, j]), _fmt(ok[i, j])])


# --------------------------------------------------------------------------- plots


def _flexible_columns(cols: Mapping[str, np.ndarray], k: int = 6) -> list[str]:
    """The first ``k`` frequency columns of flexible modes, a column equal to an earlier one in every
    case (the other mode of a repeated pair) left out."""
    names = [c for c in cols if c.startswith("f") and c.endswith("_hz")]
    flex = [c for c in names if np.any(np.isfinite(cols[c])) and np.nanmax(cols[c]) >= drive_modal.RIGID_HZ]
    out: list[str] = []
    for c in flex:
        if not any(np.allclose(cols[c], cols[d], rtol=1e-6, equal_nan=True) for d in out):
            out.append(c)
    return out[:k]


def _axis_label(path: str) -> str:
    """A parameter path with its unit, drawn literally: ``belt.EI [N m^2]``."""
    from beltjax.plotting import literal

    u = parameters.unit(path)
    return literal(path, 60) + (f" [{u}]" if u else "")


def _column_label(name: str) -> str:
    """The quantity and unit of an output column (``tension_<span>_N`` -> ``span tension [N]``)."""
    for prefix, what in (("tension_", "span tension"), ("hub_", "hub force")):
        if name.startswith(prefix) and name.endswith("_N"):
            return f"{what} [N]"
    if name.startswith("f") and name.endswith("_hz"):
        return "frequency [Hz]"
    return {"installation_tension_N": "installation tension [N]", "belt_length_m": "belt length [m]",
            "tensioner_angle_deg": "tensioner arm angle [deg]", "spring_moment_Nm": "spring moment [N m]",
            "campbell_unstable_from_rpm": "unstable from [rpm]"}.get(name, name)


def plot_grid(spec: Spec, cols, path: Path, labels: list[str] | None = None) -> list[Path]:
    """Outputs against the first grid parameter (lines: the other grid axes; with random samples
    the mean over the samples and a min-max band).  Writes sweep_frequencies.png and sweep_statics.png.
    Axes carry units (the parameter's, from :func:`beltjax.parameters.unit`); lines that lie on
    each other are drawn dashed over the first with a note (:func:`beltjax.plotting.coinciding`)."""
    from beltjax.plotting import coinciding, literal, literal_wrapped, overlay_style, save, subplots

    shape = (*spec.grid_shape, spec.samples if spec.random else 1)
    x = spec.grid[0].values
    others = list(np.ndindex(*shape[1:-1])) if len(shape) > 2 else [()]
    if len(others) > 12:
        others = others[:: math.ceil(len(others) / 12)]
    written = []
    groups = [("sweep_frequencies.png", _flexible_columns(cols, 6)),
              ("sweep_statics.png", [c for c in cols if c.startswith("tension_") or c.startswith("hub_")][:6])]
    for fname, names in groups:
        if not names:
            continue
        nc = min(3, len(names))
        nr = math.ceil(len(names) / nc)
        fig, axes = subplots(nr, nc, figsize=(4.6 * nc, 3.4 * nr), squeeze=False)
        for ax, name in zip(axes.flat, names):
            Y = np.asarray(cols[name], float).reshape(shape)
            curves = []
            for o in others:
                y = Y[(slice(None), *o)]
                with warnings.catch_warnings():  # all-NaN rows (failed cases) plot as gaps
                    warnings.simplefilter("ignore", RuntimeWarning)
                    mean, lo, hi = np.nanmean(y, -1), np.nanmin(y, -1), np.nanmax(y, -1)
                lab = ", ".join(f"{literal(a.parameter, 40)} = {a.values[i]:.4g}"
                                + (f" {parameters.unit(a.parameter)}" if parameters.unit(a.parameter) else "")
                                for a, i in zip(spec.grid[1:], o)) or None
                curves.append((lab, mean, lo, hi))
            over = coinciding([c[1] for c in curves])
            for j, (lab, mean, lo, hi) in enumerate(curves):
                ls, note = overlay_style(over, [c[0] or "" for c in curves], j)
                line, = ax.plot(x, mean, marker="o" if over[j] is None else "x", ms=3, ls=ls,
                                label=lab + note if lab else None)
                if shape[-1] > 1:
                    ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2, lw=0)
            title = literal(name, 60)
            if labels and name.startswith("f") and name[1:-3].isdigit():
                m = int(name[1:-3]) - 1
                if m < len(labels):
                    title = f"{literal(name, 60)}: {literal(labels[m], 60)}"
            ax.set_title(title, fontsize=8)
            ax.set_xlabel(_axis_label(spec.grid[0].parameter), fontsize=8)
            ax.set_ylabel(_column_label(name), fontsize=8)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            if curves[0][0] and name == names[0]:
                ax.legend(fontsize=6)
        for ax in list(axes.flat)[len(names):]:
            ax.set_visible(False)
        note = " (mean over the random samples; band: min-max)" if shape[-1] > 1 else ""
        if fname == "sweep_frequencies.png":
            note += ("\nf_k: the nominal scene's k-th mode, followed into every case by its shape (a column equal to "
                     "an earlier one in every case, a repeated pair's, is drawn once)" if labels else
                     "\nf_k: the k-th frequency of each case, sorted (a mode may change rank across cases)")
        fig.suptitle(literal_wrapped(spec.description or "parametric sweep", 120) + note, fontsize=9)
        save(fig, path / fname, dpi=100)
        written.append(path / fname)
    return written


def plot_histograms(spec: Spec, cols, path: Path, labels: list[str] | None = None) -> Path | None:
    """Histograms of span tensions and of the lowest flexible frequencies (sweep_histograms.png);
    x axes: the quantity and its unit, y axes: the number of cases."""
    from beltjax.plotting import literal, literal_wrapped, save, subplots

    names = [c for c in cols if c.startswith("tension_")] + _flexible_columns(cols, 4)
    names += [c for c in ("belt_length_m", "tensioner_angle_deg") if c in cols]
    names = [c for c in names if np.any(np.isfinite(np.asarray(cols[c], float)))]
    if not names:
        return None
    nc = min(3, len(names))
    nr = math.ceil(len(names) / nc)
    fig, axes = subplots(nr, nc, figsize=(4.4 * nc, 3.4 * nr), squeeze=False)
    for ax, name in zip(axes.flat, names):
        y = np.asarray(cols[name], float)
        y = y[np.isfinite(y)]
        ax.hist(y, bins=min(40, max(5, int(np.sqrt(y.size)))), color="tab:blue", alpha=0.8)
        title = literal(name, 60)
        if labels and name.startswith("f") and name[1:-3].isdigit() and int(name[1:-3]) - 1 < len(labels):
            title = f"{title}: {literal(labels[int(name[1:-3]) - 1], 60)}"
        ax.set_title(f"{title}\nmean {y.mean():.5g}, std {y.std():.3g}", fontsize=8)
        ax.set_xlabel(_column_label(name), fontsize=8)
        ax.set_ylabel("cases", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    fig.suptitle(literal_wrapped(spec.description or "random sweep", 120), fontsize=9)
    save(fig, path / "sweep_histograms.png", dpi=100)
    return path / "sweep_histograms.png"


def plot_campbell_band(result, path: Path, drive_name: str, orders=(1.0, 2.0, 3.0)) -> Path:
    """Campbell curves of every case (thin lines) with order lines (sweep_campbell.png): one colour
    per mode (the nominal's, followed by its shape), its label in the legend.  A mode whose
    curves lie on an earlier mode's in every case is drawn dashed over it, with a note."""
    from beltjax.plotting import coinciding, colormap, literal, overlay_style, save, subplots

    rpm, F = result["campbell_rpm"], result["campbell_hz"]
    fig, ax = subplots(figsize=(10, 6))
    flex = [m for m in range(F.shape[2]) if np.any(np.isfinite(F[:, :, m])) and np.nanmax(F[:, :, m]) >= drive_modal.RIGID_HZ]
    colour = colormap(10)
    alpha = max(0.05, min(0.8, 8.0 / max(F.shape[0], 1)))
    over = coinciding([F[:, :, m] for m in flex])
    labels = result.get("campbell_mode_labels") or []
    names = [f"mode {m + 1}" + (f": {literal(labels[m], 60)}" if m < len(labels) else "") for m in flex]
    for j, m in enumerate(flex):
        ls, note = overlay_style(over, names, j)
        for i in range(F.shape[0]):
            ax.plot(rpm, F[i, :, m], color=colour(j), lw=0.8 if over[j] is None else 1.2, ls=ls, alpha=alpha,
                    label=names[j] + note if i == 0 else None)
    top = 1.2 * np.nanmax(F[:, 0, flex]) if flex and np.any(np.isfinite(F[:, 0, flex])) else 100.0
    ax.set_ylim(0, top)
    for k in orders:
        ax.plot(rpm, k * rpm / 60.0, ls="--", color="0.35", lw=1.0)
    ax.set_xlabel(f"{literal(drive_name, 60)} speed [rpm]")
    ax.set_ylabel("natural frequency [Hz]")
    ax.set_title(f"Campbell diagrams of {F.shape[0]} cases (order lines {', '.join(f'{k:g}x' for k in orders)})",
                 fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    save(fig, path / "sweep_campbell.png", dpi=100)
    return path / "sweep_campbell.png"


# --------------------------------------------------------------------------- the command


def progress_bar(label: str = "sweep") -> Callable[[int, int], None]:
    """A progress callback drawing ``label [#####     ] done/total cases (elapsed)`` on stderr
    (:func:`beltjax.progress.counter`: redrawn in place on a terminal, whole lines elsewhere)."""
    from beltjax.progress import counter

    return counter(f"  {label}", "cases")


def summary_table(cols: Mapping[str, np.ndarray], stats: Mapping[str, dict], labels: list[str] | None = None,
                  max_rows: int = 40) -> str:
    """A readable table of the statistics of the output columns."""
    names = []
    for name in list(cols)[:max_rows]:
        if name in ("converged", "stable"):
            continue
        lab = name
        if labels and name.startswith("f") and name[1:-3].isdigit() and int(name[1:-3]) - 1 < len(labels):
            lab = f"{name} {labels[int(name[1:-3]) - 1]}"
        names.append((name, lab))
    w = max([len("output"), *(len(lab) for _, lab in names)])  # the longest name, never cut
    lines = [f"{'output':<{w}} {'mean':>11} {'std':>10} {'min':>11} {'max':>11} {'p5':>11} {'p95':>11}"]
    f = lambda x: f"{x:>11.5g}" if x is not None else f"{'-':>11}"  # noqa: E731
    for name, lab in names:
        s = stats[name]
        lines.append(f"{lab:<{w}} {f(s['mean'])} {f(s['std'])[1:]} {f(s['min'])} {f(s['max'])} {f(s['p5'])} "
                     f"{f(s['p95'])}")
    if len(cols) > max_rows:
        lines.append(f"({len(cols) - max_rows} more columns in sweep.json)")
    return "\n".join(lines)


def report(scene: Scene, spec: Spec, values: Mapping[str, np.ndarray], result: Mapping[str, np.ndarray],
           nominal: tuple[list[str], list[float]] | None = None, timing: Mapping[str, Any] | None = None) -> dict:
    """sweep.json contents: the spec, the statistics of every output column, the failures by
    cause, the nominal scene's modes and ``timing`` (wall time, cases per second...)."""
    cols = columns(scene, result)
    fails = failures(result)
    return {
        "scene": str(scene.source),
        "sweep_file": str(spec.source),
        "spec": spec.raw,
        "description": spec.description,
        "n_cases": len(result["status"]),
        "parameters": {p: statistics(v) for p, v in values.items()},
        "nominal": {p: nominal_value(scene, p) for p in spec.parameters},
        "outputs": list(spec.outputs),
        "columns": ["case", *values, *cols, "status"],
        "nominal_modes": None if nominal is None else {"labels": nominal[0], "frequencies_hz": nominal[1]},
        "frequency_columns": _columns_meaning(result),
        "summary": {k: statistics(v) for k, v in cols.items() if k not in ("converged", "stable")},
        "ok": int(np.sum(result["status"] == "ok")),
        "failed": int(sum(v["count"] for k, v in fails.items() if k != "unstable")),
        "unstable": fails.get("unstable", {}).get("count", 0),
        "failures": fails,
        **(timing or {}),
    }


def _columns_meaning(result: Mapping[str, Any]) -> str | None:
    """What the f<k>_hz (and sweep_campbell.csv) columns hold, for sweep.json."""
    if "frequencies_hz" not in result and "campbell_hz" not in result:
        return None
    if result.get("mode_labels") or result.get("campbell_mode_labels"):
        return ("f<k>_hz: the nominal scene's k-th mode (nominal_modes), followed into every case by its shape "
                "(mass-weighted MAC, optimal assignment; NaN: not found); mode_match: a case's lowest MAC")
    return "f<k>_hz: the k-th lowest frequency of each case (sorted: the nominal scene has no modes to follow)"


def plots(scene: Scene, spec: Spec, result: Mapping[str, np.ndarray], out: Path,
          labels: list[str] | None = None) -> list[Path]:
    """The sweep's figures in ``out``: outputs against the grid parameters, histograms of a
    random study, Campbell curves of every case (PNG paths written)."""
    cols = columns(scene, result)
    files: list[Path] = []
    if spec.grid:
        files += plot_grid(spec, cols, out, labels)
    if spec.random:
        h = plot_histograms(spec, cols, out, labels)
        if h is not None:
            files.append(h)
    if "campbell_hz" in result:
        files.append(plot_campbell_band(result, out, scene.route.order[drive.drive_pulley(scene)]))
    return files


def run(scene: Scene, spec_path: str | os.PathLike, out: str | os.PathLike, backend: str = "local") -> int:
    """``beltjax sweep``: read the sweep file, evaluate every case, write sweep.csv, sweep.json and
    plots to ``out``, print a summary; returns the exit status (1 when every case failed).

    Raises :class:`SweepError` (one line naming the key) for a bad sweep file.
    """
    spec = load_spec(spec_path)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    values = cases(scene, spec)
    n = spec.n_cases
    print(f"sweep of {scene.source} by {spec.source}: {n} cases"
          + (f" (grid {' x '.join(str(s) for s in spec.grid_shape)})" if spec.grid else "")
          + (f" ({spec.samples} random samples{' per grid point' if spec.grid else ''})" if spec.random else "")
          + f"; outputs {', '.join(spec.outputs)}; backend {backend}")
    if backend == "dask":
        _dask_client_check()
    refs = (sweep_modes.references(scene, spec.outputs, spec.modes, spec.rpm)
            if "modal" in spec.outputs or "campbell" in spec.outputs else {})
    ref = refs.get("modal") if "modal" in spec.outputs else refs.get("campbell")
    nominal = (list(ref[1]), [float(x) for x in ref[0].freqs]) if ref else None
    labels = nominal[0] if nominal else None
    t0 = time.perf_counter()
    first: list[float] = []
    bar = progress_bar()

    def progress(done, total):
        if not first:
            first.append(time.perf_counter() - t0)
        bar(done, total)

    result = evaluate(scene, values, spec.outputs, spec.modes, spec.rpm, chunk=spec.chunk, progress=progress,
                      backend=backend, dask=spec.dask_scheduler, reference=refs or None)
    wall = time.perf_counter() - t0
    devices = _devices() if backend == "local" else None
    size = _chunk_size(n, spec.chunk, 0 if spec.rpm is None else len(spec.rpm), devices)
    steady = (n - size) / (wall - first[0]) if first and n > size and wall > first[0] else None
    timing = {"backend": backend, "devices": [str(d) for d in (devices or jax.local_devices()[:1])]
              if backend == "local" else None, "chunk": size, "wall_s": wall,
              "first_chunk_s": first[0] if first else None, "cases_per_s": n / wall if wall > 0 else None,
              "cases_per_s_after_first_chunk": steady}
    data = report(scene, spec, values, result, nominal, timing)
    cols = columns(scene, result)
    write_csv(out / "sweep.csv", values, cols, result["status"])
    (out / "sweep.json").write_text(json.dumps(_jsonable(data), indent=2) + "\n")
    files = [out / "sweep.csv", out / "sweep.json"]
    if "campbell_hz" in result:
        write_campbell_csv(out / "sweep_campbell.csv", result)
        files.append(out / "sweep_campbell.csv")
    files += plots(scene, spec, result, out, labels)
    print(f"{n} cases in {wall:.1f} s ({n / wall:.3g} cases/s"
          + (f"; {steady:.3g} cases/s after the first chunk, which compiles in {first[0]:.1f} s" if steady else "")
          + ")")
    print(f"{data['ok']} ok, {data['failed']} failed, {data['unstable']} unstable")
    for s, v in data["failures"].items():
        print(f"  {s}: {v['count']} cases ({v['reason']}); first: {', '.join(str(i) for i in v['cases'][:8])}")
    print(summary_table(cols, data["summary"], labels))
    if labels:
        print("(f<k>: the nominal scene's k-th mode, followed into every case by its shape; mode_match: a case's "
              "lowest MAC with the nominal's modes)")
        low = np.asarray(cols.get("mode_match", []), float)
        n_low = int(np.sum(low < mode_tracking.UNCERTAIN_MAC))
        if n_low:
            print(f"note: in {n_low} cases a mode's shape differs from the nominal's (mode_match < "
                  f"{mode_tracking.UNCERTAIN_MAC:g}; NaN: not found): its column holds the closest mode")
    from beltjax.outputs import wrote

    wrote(files)  # printed here, or by the command line once the files are moved into --out
    if data["ok"] + data["unstable"] == 0:
        print("beltjax: every case failed (see the status column of sweep.csv)", file=sys.stderr)
        return 1
    return 0


def _dask_client_check() -> None:
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise SweepError("backend", "the dask backend needs dask.distributed: pip install 'beltjax[dask]'") from None


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    return x
