"""Responses over engine speed: the periodic steady state at each speed of a list
(:func:`beltjax.orders.steady.steady_case`), batched with ``vmap`` in padded chunks of one
compiled shape, the speeds that had not settled run again with a longer settling time, and the
result gathered with a status per speed."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import drive, friction, parameters, schema, validate
from beltjax.drive import belt_slip
from beltjax.errors import BeltjaxError
from beltjax.orders.steady import (CHANNELS, MAX_REVOLUTIONS, METHODS, SOLVERS, STARTS, Settings, cycle_revolutions,
                                   fixed_step, for_scene, settle_cycles, steady_case)
from beltjax.scene import Scene
from beltjax.transient_outputs import UNITS, _columns

#: settling residual (-) above which a speed counts as not settled (:func:`steady_case`)
SETTLE_TOL = 1e-2
#: the settling time of the speeds that had not settled is multiplied by this, once
RETRY_FACTOR = 4.0
#: most speeds of one response
MAX_SPEEDS = 2000
#: the longest settling transient per speed (s): a drive still moving after it has no steady state
#: to report (and a speed that has not settled runs RETRY_FACTOR times longer)
MAX_SETTLE_S = 100.0
#: samples per excitation cycle accepted
MIN_SAMPLES, MAX_SAMPLES = 16, 4096
#: the status of a speed, worst first (overloaded: the mean loads would stretch a span past 2 % or
#: wind the tensioner arm round, :func:`beltjax.statics.operating_faults`; span_slack: a span's
#: force on the pulleys, its tension less rhoA c^2 lam with transport, fell to 0 or below in the
#: cycle: the belt lifts off, no grip)
STATUS = ("not_converged", "overloaded", "supercritical", "solver_failed", "span_slack", "not_settled", "ok")  # first cause first
#: the statuses that flag a computed cycle, whose numbers are kept beside the flag (a span going slack
#: in the cycle, a cycle not yet repeating); every other status but "ok" leaves no state to report
#: (statics not converged, an overloaded operating point, one past a span's critical speed, a
#: failed transient): its numbers are NaN.  The one policy of responses over speed and of sweeps (beltjax.sweep.batch).
FLAGS_KEEPING_NUMBERS = ("span_slack", "not_settled")


def settle_problem(settle_s) -> str | None:
    """What is wrong with a settling time ``settle_s`` (s) per speed, or None: the check of
    ``beltjax orders`` and of a sweep's ``settle_s``."""
    if not (math.isfinite(settle_s) and 0 <= settle_s <= MAX_SETTLE_S):
        return (f"must be a finite time in [0, {MAX_SETTLE_S:g}] s (a drive still moving after {MAX_SETTLE_S:g} s "
                f"has no steady state to report), got {settle_s!r}")
    return None


class OrdersError(BeltjaxError):
    """A response over speed that cannot be run (one-line message naming the key)."""


def needs_rerun(out: dict, settle_tol: float = SETTLE_TOL):
    """True (numpy or JAX, per speed or case) where the periodic state was not reached: the
    settling residual (-) above ``settle_tol`` (inf where the shooting found no attracting or neutral cycle)
    while the statics converged, the transient reached its end and the operating point is below
    the critical speed and not overloaded (such a speed is flagged, not run again).  ``out``: the
    arrays ``settling``, ``solver_ok``, ``converged``, ``supercritical`` and ``overloaded`` of
    :func:`~beltjax.orders.steady.steady_case`.  The one rule of :func:`response_over_speed` and
    of a sweep's ``response`` output."""
    return (~(out["settling"] <= settle_tol) & (out["solver_ok"] > 0.5) & (out["converged"] > 0.5)
            & (out["supercritical"] < 0.5) & (out["overloaded"] < 0.5))


def fallback_passes(method: str, settle_s: float) -> list[tuple[float, str]]:
    """The passes, in order, that the speeds (or cases) still :func:`needs_rerun` run again, as
    (settling time in s, method): after the shooting, the settling transient for ``settle_s``;
    then (after the settling method too) for :data:`RETRY_FACTOR` times it."""
    passes = [(settle_s, "settle"), (settle_s * RETRY_FACTOR, "settle")]
    return passes if method == "shooting" else passes[1:]


def replaced_by(again_ok, earlier_settled):
    """Which speeds (or cases) of a re-run pass take its results (bool array): all but those whose
    re-run failed (``again_ok`` False: its solver stopped, e.g. out of steps) where the earlier
    results came from a settling transient that reached its end (``earlier_settled``, one bool or
    per speed), which keep
    those, flagged as not settled, rather than a failure's NaN.  A shooting's results that gave
    up are replaced whatever happens (they are not a transient's state)."""
    return np.asarray(again_ok, dtype=bool) | ~np.asarray(earlier_settled, dtype=bool)


def check(scene: Scene, rpm) -> None:
    """Refuse (:class:`OrdersError`) what has no periodic steady state in crank angle: a drive
    pulley that is not driven, a run-up, excitation at a fixed frequency (Hz) or a crank trace
    against time, loads that switch on or off or vary at a fixed frequency, span loads, the hybrid model's transient
    with ``belt_slip``; speeds that are not positive and finite."""
    rpm = np.asarray(rpm, dtype=float)
    if rpm.ndim != 1 or rpm.size == 0:
        raise OrdersError("rpm: give at least one speed", "rpm")
    if rpm.size > MAX_SPEEDS:
        raise OrdersError(f"rpm: {rpm.size} speeds, at most {MAX_SPEEDS}", "rpm")
    if np.any(rpm <= 0):  # (the accepted range of a drive speed admits 0)
        raise OrdersError(f"rpm: every speed must be > 0 rpm (a crank at rest has no excitation cycle), "
                          f"got {float(rpm[rpm <= 0][0]):g}", "rpm")
    try:
        validate.speeds(rpm, "rpm", "drive.rpm")  # finite, in the accepted range of a drive speed
    except BeltjaxError as exc:
        raise OrdersError(str(exc), exc.key) from None
    if refused := belt_slip.transient_check(scene):
        raise OrdersError(f"{refused[0]}: {refused[1]}", refused[0])
    d = scene.route.order[drive.drive_pulley(scene)]
    if not scene.pulley(d).driven:  # (an isolated crank's rim is free, its hub driven)
        raise OrdersError(f"pulley {d!r}: a response over speed needs a driven drive pulley (driven = true): "
                          "its speed_rpm is what the response runs over", f"pulley.{d}.driven")
    p = scene.pulley(d)
    if float(p.acceleration_rpm_per_s) != 0.0:
        raise OrdersError(f"pulley.{d}.acceleration_rpm_per_s: a run-up has no steady state; give 0 for a response "
                          "over speed", f"pulley.{d}.acceleration_rpm_per_s")
    if float(p.fluctuation_amplitude_deg) != 0.0:
        raise OrdersError(f"pulley.{d}.fluctuation_frequency_hz: a fluctuation at a fixed frequency does not follow "
                          "the speed; give it as a [[fluctuation]] order", f"pulley.{d}.fluctuation_frequency_hz")
    for i, f in enumerate(scene.fluctuations):
        key = f.key or f"fluctuation[{i}]"
        if f.per != "rev":
            what = "a crank trace against time" if f.file else "a frequency in Hz"
            raise OrdersError(f"{key}: {what} does not follow the speed; give orders (order = ...) or a trace against "
                              "crank angle for a response over speed", key)
    n = cycle_revolutions(scene)  # every order, whole cycles or not, must repeat over it
    for i, f in enumerate(scene.fluctuations):
        if abs(float(f.rate) * n - round(float(f.rate) * n)) > 1e-9:
            key = f.key or f"fluctuation[{i}]"
            raise OrdersError(f"{key}: order {float(f.rate):g} repeats over no cycle of at most {MAX_REVOLUTIONS} crank "
                              "revolutions (give orders in steps of 1/2, 1/3, ... 1/8)", key)
    for i, load in enumerate(scene.torques):
        if load.t_end_s is not None or float(load.t_start_s) > 0.0:
            raise OrdersError(f"torque[{i}]: a load that switches on or off has no steady state; leave out t_start_s "
                              "and t_end_s for a response over speed", f"torque[{i}]")
        if float(load.amplitude_Nm) != 0.0:
            raise OrdersError(f"torque[{i}].amplitude_Nm: a load varying at a fixed frequency does not follow the "
                              "speed; give 0 for a response over speed", f"torque[{i}].amplitude_Nm")
    if scene.span_loads:
        raise OrdersError("span_load: span loads have no steady state; leave them out for a response over speed",
                          "span_load")


#: most fixed steps of one speed's settling transient (the hybrid model's: about 10 s per 1e4 steps
#: at 8 elements per span on a 2-core CPU)
MAX_FIXED_STEPS = 2_000_000


def fixed_steps(settings: Settings, rpm, settle_s: float) -> int:
    """The most steps (-) that one speed of ``rpm`` (rev/min) takes to settle for ``settle_s`` (s)
    and record its cycles at the fixed step of :func:`~beltjax.orders.steady.steady_case` (at most
    ``settings.dt``, whole steps per sample)."""
    period = settings.revolutions * 60.0 / np.abs(np.asarray(rpm, dtype=float))
    steps = (settle_cycles(settle_s, period) + 1.0) * period / fixed_step(period, settings.samples, settings.dt)
    return int(np.round(np.max(steps))) + 8


def check_batched(scene: Scene, what: str) -> None:
    """Refuse (:class:`OrdersError`, key ``model.fidelity``) the hybrid model where steady states
    run in vmapped batches or are differentiated (``what``: a sweep's ``response`` output, the
    objective ``arm_motion``): its implicit step in a vmapped batch forms its Jacobian at every
    step (:func:`_batch`), and a gradient would go back through thousands of them."""
    if drive.spans_of(scene).massive:
        raise OrdersError(f"model.fidelity: {what} runs the rotational model (fidelity = \"rotational\"); the "
                          "hybrid model's response over speed runs one speed at a time with beltjax orders",
                          "model.fidelity")


def over_speed(scene: Scene, values: dict, rpm, settle_s, settings: Settings) -> dict:
    """:func:`~beltjax.orders.steady.steady_case` at every speed of ``rpm`` (S,) (rev/min), as one
    pure, vmapped function of the parameter ``values`` {path: value}: differentiable (``jax.grad``;
    with ``settings.gradients``, the default, else differentiating raises) for losses over speed,
    e.g. the largest arm motion over an idle band.  ``settings.revolutions`` and
    ``settings.top_order`` must be the scene's (:func:`~beltjax.orders.steady.for_scene`; see
    :func:`response_over_speed` for the checked, chunked entry point)."""
    check_batched(scene, "over_speed")
    return jax.vmap(lambda r: steady_case(scene, values, r, settle_s, settings))(jnp.asarray(rpm))


@functools.cache
def _batch(settings: Settings, keys: tuple[str, ...], single: bool = False) -> Callable:
    """jit(vmap(steady_case)) over (values (B, len(keys)), rpm (B,), settle_s (B,)); one per settings.
    ``single``: batches of one, run without vmap (a vmapped branch runs both sides of every
    ``lax.cond``: the hybrid model's implicit step would form its Jacobian at every step; measured
    on the eight-pulley drive at 4 elements per span, one speed, 2.3 s without vmap and 183 s in a
    vmapped batch of one, the same cycle to 1e-14; the rotational shooting is unchanged by it, 30
    speeds in 2.00 s and 1.93 s, the same cycles to 1e-10: benchmarks/bench_orders_hybrid.py
    --vmap-check)."""

    def one(scene, x, rpm, settle):
        return steady_case(scene, dict(zip(keys, x)), rpm, settle, settings)

    if single:
        return jax.jit(lambda scene, x, rpm, settle: jax.tree_util.tree_map(
            lambda v: v[None], one(scene, x[0], rpm[0], settle[0])))
    return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0)))


#: on an accelerator, a fallback pass of at most this many speeds (or a sweep's cases) runs on the
#: host's CPU: a lock-step batch costs a GPU about 1 ms a step (benchmarks/README.md section 5g),
#: whatever its size, and a CPU about 50 us a step of one speed, so a few stragglers of thousands of
#: steps each (the dry-friction tensioner's settling transients) finish sooner there
HOST_FALLBACK_MAX = 16


def fallback_device(n: int, hybrid: bool = False):
    """The device a pass of ``n`` speeds or cases runs on: for a fallback pass, the host's CPU when
    the default backend is an accelerator and ``n`` <= :data:`HOST_FALLBACK_MAX`, else None (the
    default).  ``hybrid``: every pass of the hybrid model, the first included, runs on the host's CPU beside an accelerator (one
    speed at a time, a sequence of small implicit steps: on one H200 1.0 ms a step after a 196 s
    compilation, against 0.37 ms a step after about 38 s on a 2-core CPU; a vmapped batch of
    128 had not compiled and run in 290 s: benchmarks/README.md section 5g)."""
    if jax.default_backend() == "cpu" or (n > HOST_FALLBACK_MAX and not hybrid):
        return None
    try:
        return jax.devices("cpu")[0]
    except RuntimeError:  # no CPU backend
        return None


def default_chunk(n: int, method: str = "shooting") -> int:
    """Speeds per compiled batch: all of them on an accelerator; on a CPU one at a time for the
    shooting (a batch runs in lock-step, and its variational equations cost in proportion to the
    batch: on the eight-pulley drive 100 speeds took 10.4 s one by one, 17.4 s in batches of 25,
    benchmarks/bench_orders.py), up to 32 for the settling transient (the chunks give progress).
    The hybrid model runs one speed at a time on every backend (:func:`response_over_speed`: in a
    vmapped batch its implicit step forms its Jacobian at every step, :func:`_batch`)."""
    if jax.default_backend() != "cpu":
        return max(1, n)
    if method == "shooting":
        return 1
    return max(1, -(-n // -(-n // 32)))  # chunks of at most 32, as even as can be (less padding)


@dataclasses.dataclass
class OrdersResult:
    """A response over speed.

    rpm (S,) the drive pulley's speeds; stats: ``{channel}:{stat}`` -> (S, ...) arrays
    (:func:`beltjax.orders.steady.steady_case`), min_slip_margin (S, arcs), max_friction_needed
    (S, n); hub_forces_N (S, K, bearings, 2) over the cycle, t_s (S, K); status (S,) of
    :data:`STATUS`; settling (S,); columns: channel -> column labels; orders: the crank orders of
    the ``:orders`` arrays; units: channel -> unit; meta: settings, times, steps."""

    rpm: np.ndarray
    stats: dict
    columns: dict
    orders: list
    status: list
    settling: np.ndarray
    units: dict
    meta: dict

    def channel(self, name: str, stat: str) -> np.ndarray:
        """The (S, ...) array of one channel's statistic (mean, min, max, p2p or orders)."""
        return self.stats[f"{name}:{stat}"]

    def to_json(self) -> dict:
        """JSON-ready: speeds, status, every statistic with its columns and units."""
        stats = {k: np.asarray(v) for k, v in self.stats.items() if k not in ("hub_forces_N", "t_s")}
        return dict(meta=self.meta, rpm=self.rpm, status=self.status, settling=self.settling, orders=self.orders,
                    units=self.units, columns=self.columns, stats=stats)


def _status(out: dict, settle_tol: float) -> list[str]:
    conds = dict(
        not_converged=out["converged"] < 0.5,
        solver_failed=out["solver_ok"] < 0.5,
        overloaded=out["overloaded"] > 0.5,
        supercritical=out["supercritical"] > 0.5,
        span_slack=out["min_span_force_N"] <= 0.0,
        not_settled=~(out["settling"] <= settle_tol),
    )
    res = []
    for i in range(len(out["settling"])):
        res.append(next((k for k in STATUS[:-1] if conds[k][i]), "ok"))
    return res


def response_over_speed(scene: Scene, rpm, *, values: dict | None = None, settle_s: float = 1.0,
                        settings: Settings | None = None, chunk: int | None = None,
                        settle_tol: float = SETTLE_TOL, progress: Callable[[int, int], None] | None = None
                        ) -> OrdersResult:
    """The periodic steady state of ``scene`` at each drive-pulley speed of ``rpm`` (rev/min):
    per channel its mean, min, max, peak-to-peak and order amplitudes over one excitation cycle,
    the least slip margin of each arc, the hub-force loci.

    values: {parameter path: value} set on the scene for every speed; settle_s: transient time
    (s) before the recorded cycle of the settling method (speeds that the shooting did not bring to
    an attracting cycle settle for that long; those whose settling residual stays above
    ``settle_tol`` are run again with :data:`RETRY_FACTOR` times it, then flagged
    ``not_settled``; ``meta["methods"]`` says which gave each speed); settings:
    :class:`~beltjax.orders.steady.Settings` (samples per cycle, highest order, tolerances; run
    with ``gradients=False`` whatever given: the results are numbers, not differentiable);
    chunk: speeds per compiled batch (:func:`default_chunk`); progress(done, total).  Raises
    :class:`OrdersError` for a scene or speeds without a steady state in crank angle
    (:func:`check`)."""
    scene = drive.canonical(scene)
    try:
        rpm = np.asarray(rpm if rpm is not None else (), dtype=float).ravel()
    except (TypeError, ValueError):
        raise OrdersError(f"rpm: expected an array of speeds (rev/min), got {rpm!r}", "rpm") from None
    given = settings or Settings()  # its choices checked before any work on the scene
    if given.solver not in SOLVERS:
        raise OrdersError(f"solver: {given.solver!r}; choose one of {', '.join(SOLVERS)}", "solver")
    if given.start not in STARTS:
        raise OrdersError(f"start: {given.start!r}; choose one of {', '.join(STARTS)}", "start")
    if given.method not in METHODS:
        raise OrdersError(f"method: {given.method!r}; choose one of {', '.join(METHODS)}", "method")
    check(scene, rpm)
    chunk = None if chunk is None else validate.count(chunk, "chunk")
    problem = settle_problem(settle_s)
    if problem:
        raise OrdersError(problem, "settle_s")
    values = dict(values or {})
    for k, val in values.items():
        parameters.check(scene, k)
        if np.ndim(val) != 0 or np.asarray(val).dtype.kind not in "biuf":
            raise OrdersError(f"values: {k}: expected one number, set for every speed, got {val!r}", "values")
        parameters.check_value(k, val)
    validate.positive(settle_tol, "settle_tol")
    settings = dataclasses.replace(for_scene(scene, settings), gradients=False)  # numbers out, no derivative
    # (a scene's simulation.rtol has the same ceiling: beyond it the error control lets the response go)
    validate.positive(settings.rtol, "rtol", "step tolerance", upper=schema.FIELDS["simulation.rtol"].high)
    validate.positive(settings.atol, "atol", "step tolerance")
    validate.count(settings.max_steps, "max_steps")
    if not MIN_SAMPLES <= settings.samples <= MAX_SAMPLES:
        raise OrdersError(f"samples: {settings.samples} samples per cycle; give {MIN_SAMPLES} to {MAX_SAMPLES}", "samples")
    need = 2 * settings.max_order * settings.revolutions + 2
    if not (math.isfinite(settings.max_order) and settings.max_order * settings.revolutions >= 1):
        raise OrdersError(f"max_order: {settings.max_order!r} reports no order of a {settings.revolutions}-revolution "
                          "cycle; give at least 1 / (revolutions per cycle)", "max_order")
    if settings.samples < need:
        raise OrdersError(f"max_order: order {settings.max_order:g} needs at least {math.ceil(need)} samples per cycle "
                          f"(now {settings.samples}): raise samples or lower max_order", "max_order")
    keys = tuple(sorted(values))
    x = np.asarray([[float(values[k]) for k in keys]], dtype=float)
    hybrid = drive.spans_of(scene).massive
    if hybrid:  # one speed at a time (default_chunk, _batch), and room for the longest pass's fixed steps
        chunk = 1
        if settings.dt is not None:
            steps = fixed_steps(settings, rpm, settle_s * RETRY_FACTOR)
            if steps > MAX_FIXED_STEPS:
                raise OrdersError(f"settle_s: {settle_s:g} s (and a re-run {RETRY_FACTOR:g}x longer) at "
                                  f"{settings.samples} samples per cycle needs {steps} steps of the hybrid model's "
                                  f"fixed step, more than {MAX_FIXED_STEPS}: shorten settle_s or lower samples", "settle_s")
            settings = dataclasses.replace(settings, max_steps=max(settings.max_steps, steps))
    size = chunk or default_chunk(rpm.size, settings.method)

    def run(batch, speeds, settle, size=size):
        parts, done = [], 0
        fn = batch(single=size == 1)
        for a in range(0, speeds.size, size):
            r = speeds[a : a + size]
            pad = np.concatenate([r, np.full(size - r.size, r[-1])])
            got = fn(scene, jnp.asarray(np.repeat(x, size, axis=0)), jnp.asarray(pad), jnp.full(size, settle))
            parts.append({k: np.asarray(v)[: r.size] for k, v in got.items()})
            done += r.size
            if progress is not None:
                progress(done, speeds.size)
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    t0 = time.perf_counter()
    place = fallback_device(rpm.size, hybrid) if hybrid else None  # the hybrid model: on the host's CPU
    with jax.default_device(place) if place is not None else contextlib.nullcontext():
        out = run(functools.partial(_batch, settings, keys), rpm, settle_s)
    # the speeds that had not settled: a shooting that did not converge to an attracting cycle runs
    # the settling transient, and a transient that had not settled runs again RETRY_FACTOR x longer
    rerun = np.zeros(rpm.size, dtype=bool)
    used = [settings.method if settings.method == "shooting" else f"settle {settle_s:g} s"] * rpm.size
    earlier = settings.method  # the method that gave the numbers a pass may replace
    for time_s, method in fallback_passes(settings.method, settle_s):
        retry = np.flatnonzero(needs_rerun(out, settle_tol))
        if not retry.size:
            break
        rerun[retry] = True
        host = fallback_device(retry.size, hybrid)
        with jax.default_device(host) if host is not None else contextlib.nullcontext():
            again = run(functools.partial(_batch, dataclasses.replace(settings, method=method), keys), rpm[retry],
                        time_s, (chunk or default_chunk(retry.size, method)) if host is None or hybrid
                        else retry.size)  # the host: one batch (the hybrid model: one speed at a time)
        take = replaced_by(again["solver_ok"] > 0.5, earlier == "settle")
        for i, t in zip(retry, take):
            used[i] = f"{method} {time_s:g} s" if t else f"{used[i]} (its {time_s:g} s re-run failed)"
        retry, earlier = retry[take], method
        for k in out:
            if k not in ("shooting_iterations", "shooting_cycle_steps", "floquet_multiplier"):  # (why it gave up)
                out[k][retry] = again[k][take]
    wall = time.perf_counter() - t0
    cols = _columns(scene)
    columns = {}
    for name in CHANNELS:
        if f"{name}:mean" in out:
            columns[name] = cols.get(name, [])
    order = list(scene.route.order)
    columns["max_friction_needed"] = order
    if "min_slip_margin" in out:
        columns["min_slip_margin"] = [order[i] for i in friction.given(scene)]
    columns["hub_forces_N"] = cols["hub_forces_N"]
    stats = {k: v for k, v in out.items() if ":" in k or k in ("min_slip_margin", "max_friction_needed",
                                                               "hub_forces_N", "t_s")}
    units = {k: UNITS[k] for k in CHANNELS if k in columns}
    units.update(min_slip_margin="-", max_friction_needed="-", hub_forces_N="N")
    meta = dict(
        fidelity=scene.model.fidelity, drive_pulley=order[drive.drive_pulley(scene)], settle_s=settle_s,
        settle_tol=settle_tol, rerun_speeds=int(rerun.sum()), method=settings.method, methods=used,
        shooting_iterations=out["shooting_iterations"].astype(int).tolist(),
        shooting_cycle_steps=out["shooting_cycle_steps"].astype(int).tolist(),
        floquet_multipliers=[None if not np.isfinite(m) else float(m) for m in out["floquet_multiplier"]],
        revolutions_per_cycle=settings.revolutions,
        samples_per_cycle=settings.samples, rtol=settings.rtol, atol=settings.atol, solver=settings.solver,
        dt_s=settings.dt,
        steps=out["steps"].astype(int).tolist(), t_end_s=out["t_end_s"].tolist(), wall_s=wall, chunk=size,
        values={k: float(v) for k, v in values.items()},
    )
    status = _status(out, settle_tol)
    return OrdersResult(rpm=rpm, stats=blank_failed(stats, status), columns=columns, orders=settings.orders(),
                        status=status, settling=out["settling"], units=units, meta=meta)


def blank_failed(stats: dict, status) -> dict:
    """``stats`` with NaN at the speeds whose status leaves no state to report (every status but
    "ok" and :data:`FLAGS_KEEPING_NUMBERS`), the sample times kept."""
    failed = ~np.isin(np.asarray(status), ("ok", *FLAGS_KEEPING_NUMBERS))
    return {k: v if k == "t_s" or not failed.any() else
            np.where(failed.reshape((-1,) + (1,) * (np.ndim(v) - 1)), np.nan, v) for k, v in stats.items()}
