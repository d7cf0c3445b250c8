"""The batched evaluation of a sweep's cases: one compiled, vmapped function run in padded chunks
(local devices), with the statics retry and the checks of each case's solved installation."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import critical, drive, drive_modal, friction, mode_batch, mode_tracking, parameters, statics, sweep_modes, validate
from beltjax.scene import Scene, require_scene
from beltjax.sweep.spec import MAX_CASES, OUTPUTS, STATUS, SweepError, _CODE, _precheck
from beltjax.sweep.chunks import _chunk_size, _devices, default_chunk  # noqa: F401 (re-exported)
from beltjax.drive.effects import effects_of
from beltjax.drive import couplings

@dataclasses.dataclass(frozen=True)
class _Options:
    """Static options of the compiled batch (hashable)."""

    outputs: tuple[str, ...]
    modes: int
    gyro: bool
    steps: int = 1
    track: int = 0
    response: Any = None  # the response's beltjax.orders.Settings (static)

#: the batch column that carries the response's settling time (s): traced, so that the fallback's
#: passes of 1x and RETRY_FACTOR x settle_s share one compiled program
SETTLE_COLUMN = "response.settle_s"

def case_outputs(scene: Scene, values: Mapping[str, Any], outputs: tuple[str, ...] = ("statics", "modal"),
                 modes: int = 12, rpm=None, gyroscopic: bool = False, steps: int = 1,
                 track: int = 0, settle_s: float = 1.0, response=None, reference=None) -> dict[str, jax.Array]:
    """Outputs of one case: ``scene`` with ``values`` {path: scalar} set (pure JAX: jit, vmap, grad).

    outputs, modes, gyroscopic (solve the gyroscopic problem of the moving belt) and steps
    (speed steps of the statics) are static.  Returns the arrays of :func:`evaluate` for one
    case (no ``status``): an integer ``code`` (index into :data:`STATUS`) and, per output,
    span_tensions_N (N), hub_forces_N (N, magnitudes), installation_tension_N (N),
    belt_length_m (m), tensioner_angle_deg (deg), spring_moment_Nm (N m), converged;
    frequencies_hz (Hz, NaN when unstable), stable; campbell_hz (Hz, per ``rpm`` speed),
    campbell_stable.  The statics run at the drive pulley's speed_rpm (m/s of belt), at the
    operating point when the scene has lasting loads (:func:`beltjax.drive.lasting_loads`;
    then also drive_torque_Nm, friction_needed per route entry and slip_margins per route entry
    with a friction coefficient), and the modes are about that state (as ``beltjax modal``).  With
    ``track`` > 0 the lowest ``track`` modes come with their mass-whitened shapes for mode
    tracking (:func:`beltjax.drive_modal.tracking_shapes`): modal_W, modal_owner, campbell_W,
    campbell_owner (the frequencies are then the lowest ``track``, sorted); with ``reference`` (n, r),
    the nominal's unit whitened shapes, also modal_proj (r, c): their projections on the case's
    (:func:`beltjax.mode_batch.projections`, the batched matching's input).  ``response``: the
    periodic steady state at the case's drive speed after ``settle_s`` s, with the static
    :class:`beltjax.orders.Settings` ``response`` (default, outside jit only:
    :func:`beltjax.orders.for_scene`)
    (:func:`beltjax.orders.steady_case`): response_arm_p2p_deg, response_span_min_N,
    response_span_max_N, response_span_p2p_N (per span), response_hub_max_N (per bearing),
    response_min_slip_margin (per arc with a coefficient), response_settling, response_rerun
    (bool: :func:`beltjax.orders.needs_rerun`, which :func:`evaluate` runs again and removes).
    """
    sc = parameters.set_values(scene, values)
    inst = statics.install(sc)
    v = drive.belt_speed(sc)
    loaded = drive.lasting_loads(sc)  # the operating point under the mean loads
    qi, inst, (conv, _, _) = statics.equilibrium(sc, inst, speed=v, steps=steps, loaded=loaded)
    out = statics.static_outputs(sc, qi, inst, v, loaded)
    faults = statics.installation_faults(sc, inst)
    names = ["no_arm_balance", "belt_slack", "belt_overstretched"]
    conds = [faults[k] for k in names]
    codes = [_CODE[k] for k in names]
    conds += [conv < 0.5, ~jnp.all(out["tensions"] > 0), out["faults"]["arm_wound"], out["faults"]["span_overstretched"],
              critical.supercritical(sc, qi, inst, v), couplings.static_overrun(qi, sc, inst)]
    codes += [_CODE[k] for k in ("not_converged", "span_slack", "arm_wound", "span_overstretched", "supercritical",
                                 "decoupler_overrun")]
    res: dict[str, jax.Array] = {}
    if "statics" in outputs:
        res["span_tensions_N"] = out["tensions"]
        res["hub_forces_N"] = jnp.linalg.norm(out["hubs"], axis=1)
        res["belt_length_m"] = inst.belt_length
        if sc.tensioner is not None:
            res["spring_moment_Nm"] = drive.spring_moment(out["theta"], sc)
        res["converged"] = conv > 0.5
        if loaded:
            need, margins = friction.arc_margins(sc, critical.span_forces(sc, qi, inst, v), out["wraps"])
            res["drive_torque_Nm"] = out["drive_torque"]
            res["friction_needed"] = need
            if margins.size:  # the arcs with a friction coefficient
                res["slip_margins"] = margins
    res["installation_tension_N"] = inst.tension  # evaluate checks each case's solved installation
    if sc.tensioner is not None:
        res["tensioner_angle_deg"] = jnp.rad2deg(out["theta"])
    stable = jnp.asarray(True)
    if "modal" in outputs:
        if track:
            t = drive_modal.tracking_shapes(sc, qi, inst, v, track, gyroscopic, full=False)
            stable, f = t["stable"], t["freqs"]
            res["modal_W"], res["modal_owner"] = t["W"], t["owner"]
            if reference is not None:
                res["modal_proj"] = mode_batch.projections(t["W"] if gyroscopic else jnp.real(t["W"]), reference, jnp)
        else:
            stable, f, *_ = drive_modal.frequencies_about(sc, qi, inst, v, gyroscopic)
            f = f[:modes]
        res["frequencies_hz"] = jnp.where(stable, f, jnp.nan)
        res["stable"] = stable
    if "campbell" in outputs:
        transport = effects_of(sc).moving_belt

        def at(r):
            vv = drive.belt_speed(sc, r)
            m = drive_modal.at_speed(sc, vv, inst, steps=statics.SPEED_STEPS, gyroscopic=transport, track=track)
            ok = m.stable & m.converged & ~m.supercritical
            if track:
                return jnp.where(ok, m.freqs, jnp.nan), ok, m.tracking["W"], m.tracking["owner"]
            return jnp.where(ok, m.freqs[:modes], jnp.nan), ok

        got = jax.vmap(at)(jnp.asarray(rpm, dtype=jnp.float64))
        res["campbell_hz"], res["campbell_stable"] = got[:2]
        if track:
            res["campbell_W"], res["campbell_owner"] = got[2:]
    if "response" in outputs:
        from beltjax.orders import SETTLE_TOL, for_scene, needs_rerun, steady_case
        from beltjax.orders.steady import speed_path

        if response is None:  # its cycle and top order are read from the scene's values: not under jit
            try:
                response = for_scene(scene)
            except jax.errors.ConcretizationTypeError:
                raise ValueError("case_outputs: the 'response' output of a traced scene needs its settings: pass "
                                 "response=beltjax.orders.for_scene(scene), computed outside the traced function"
                                 ) from None
        r = steady_case(scene, values, parameters.get_value(sc, speed_path(sc)), settle_s, response,
                        solved=(qi, inst, conv))  # the operating point solved above
        if sc.tensioner is not None:
            res["response_arm_p2p_deg"] = r["arm_angle_deg:p2p"]
        res["response_span_min_N"] = r["span_tensions_N:min"]
        res["response_span_max_N"] = r["span_tensions_N:max"]
        res["response_span_p2p_N"] = r["span_tensions_N:p2p"]
        res["response_hub_max_N"] = r["hub_force_magnitudes_N:max"]
        if "min_slip_margin" in r:
            res["response_min_slip_margin"] = r["min_slip_margin"]
        res["response_settling"] = r["settling"]
        res["response_rerun"] = needs_rerun(r)  # (the fallback's, popped by evaluate)
        conds += [r["solver_ok"] < 0.5, r["min_span_force_N"] <= 0.0, ~(r["settling"] <= SETTLE_TOL)]
        codes += [_CODE["transient_failed"], _CODE["span_slack"], _CODE["not_settled"]]
        kept = [len(conds) - 2, len(conds) - 1]  # flags on the computed cycle: its numbers are kept
    else:
        kept = []
    skip = ("frequencies_hz", "campbell_hz", *sweep_modes.SHAPE_KEYS)
    finite = [jnp.all(jnp.isfinite(x)) for k, x in res.items() if k not in skip]
    conds += [~jnp.all(jnp.asarray([*finite, True])), ~stable]
    codes += [_CODE["non_finite"], _CODE["unstable"]]
    res["code"] = jnp.select(conds, [jnp.asarray(c) for c in codes], jnp.asarray(_CODE["ok"]))
    # whether the status flags a computed cycle (beltjax.orders.FLAGS_KEEPING_NUMBERS; popped by _finish)
    res["flag_keeps"] = jnp.select(conds, [jnp.asarray(i in kept) for i in range(len(conds))], jnp.asarray(False))
    return res

def _case(scene: Scene, values: Mapping[str, jax.Array], rpm: jax.Array, opts: _Options, ref=None) -> dict:
    values = dict(values)
    settle = values.pop(SETTLE_COLUMN, 1.0)  # (a column of the batch with the response output)
    return case_outputs(scene, values, opts.outputs, opts.modes, rpm, opts.gyro, opts.steps, opts.track, settle,
                        opts.response, ref)

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
    """The jitted batch ``(scene, X (B, len(keys)), rpm (S,), ref (n, r) or None) -> outputs (B,
    ...)``, column j of X the values of parameter ``keys[j]``, ref the nominal's whitened shapes
    (:func:`case_outputs`' reference); sharded over ``devices`` (shard_map on the case axis)
    when given.  One per option set and parameter set, shared by all sweeps."""

    def batch(scene, X, rpm, ref=None):
        return jax.vmap(lambda x: _case(scene, dict(zip(keys, x)), rpm, opts, ref))(X)

    if devices is None:
        return jax.jit(batch)
    from jax.sharding import Mesh
    from jax.sharding import PartitionSpec as P

    mesh = Mesh(np.asarray(devices), ("cases",))
    return jax.jit(jax.shard_map(batch, mesh=mesh, in_specs=(P(), P("cases"), P(), P()), out_specs=P("cases"),
                                 check_vma=False))

def _matrix(values: Mapping[str, np.ndarray], keys: tuple[str, ...], size: int) -> np.ndarray:
    """(size, len(keys)) float64 values, the last case repeated to pad to ``size`` rows."""
    X = np.stack([np.asarray(values[k], dtype=float) for k in keys], axis=1)
    return np.concatenate([X, np.repeat(X[-1:], size - len(X), axis=0)]) if len(X) < size else X

def _launch_chunk(scene: Scene, values: Mapping[str, np.ndarray], rpm: np.ndarray, opts: _Options, size: int,
                  devices: tuple | None, ref=None):
    """Start one chunk (<= size cases, padded to ``size``) on the device; returns what
    :func:`_collect_chunk` needs (JAX dispatches asynchronously: the host is free meanwhile)."""
    keys = tuple(sorted(values))
    return keys, values, ref, _batch_fn(opts, devices, keys)(scene, _matrix(values, keys, size), rpm, ref)

def _collect_chunk(scene: Scene, launched, rpm: np.ndarray, opts: _Options, size: int,
                   devices: tuple | None) -> dict[str, np.ndarray]:
    """The outputs of a launched chunk as numpy (the shapes of sweep_modes.DEVICE_KEYS stay on the
    device: the tracking fetches the few cases it needs); cases whose statics did not converge
    are run again with speed stepping (statics.RETRY_STEPS), as :func:`beltjax.statics.analyse_statics` does."""
    keys, values, ref, raw = launched
    n = len(next(iter(values.values())))
    lazy = sweep_modes.DEVICE_KEYS
    out = {k: a[:n] if k in lazy else np.array(np.asarray(a)[:n]) for k, a in raw.items()}
    again = np.flatnonzero(out["code"] == _CODE["not_converged"])
    if again.size:
        fn8 = _batch_fn(dataclasses.replace(opts, steps=statics.RETRY_STEPS), devices, keys)
        redo = fn8(scene, _matrix({k: np.asarray(values[k])[again] for k in keys}, keys, size), rpm, ref)
        for k in out:
            if k in lazy:
                out[k] = out[k].at[again].set(redo[k][: again.size])
            else:
                out[k][again] = np.asarray(redo[k])[: again.size]
    return out

def _run_chunk(scene: Scene, values: Mapping[str, np.ndarray], rpm: np.ndarray, opts: _Options,
               size: int, devices: tuple | None, ref=None) -> dict[str, np.ndarray]:
    """One chunk (<= size cases), padded to ``size``, its outputs (with the retry)."""
    return _collect_chunk(scene, _launch_chunk(scene, values, rpm, opts, size, devices, ref), rpm, opts, size, devices)

def _slices(n: int, size: int) -> list[slice]:
    return [slice(s, min(s + size, n)) for s in range(0, n, size)]

def _run_local(scene: Scene, chunks: list[dict], rpm: np.ndarray, opts: _Options, size: int,
               devices: tuple | None, progress, post=lambda r: r, ref=None) -> list[dict]:
    """The chunks one after the other in this process (``post`` applied to each chunk's outputs).
    On accelerators the next chunk is launched before this one's outputs are collected and
    post-processed, so that the host's work (the mode tracking) overlaps the device's, and chunks
    are post-processed in POST_THREADS threads (numpy releases the GIL: on an H200 the tracking of
    2,048 cases took longer than their computation); on CPU one computation at a time (two in
    flight on XLA's one-thread CPU pool could wait on each other: :mod:`beltjax.runtime`)."""
    results, done, n = [], 0, sum(len(next(iter(c.values()))) for c in chunks)
    ahead = (devices or tuple(jax.local_devices()[:1]))[0].platform != "cpu"
    with ThreadPoolExecutor(POST_THREADS) as pool:
        pending = _launch_chunk(scene, chunks[0], rpm, opts, size, devices, ref) if chunks else None
        for i, c in enumerate(chunks):
            if pending is None:
                pending = _launch_chunk(scene, c, rpm, opts, size, devices, ref)
            nxt = _launch_chunk(scene, chunks[i + 1], rpm, opts, size, devices, ref) if ahead and i + 1 < len(chunks) else None
            got = _collect_chunk(scene, pending, rpm, opts, size, devices)
            results.append(pool.submit(post, got) if ahead else post(got))
            if ahead and len(results) > POST_THREADS:  # at most POST_THREADS chunks wait for their tracking
                results[-POST_THREADS - 1].result()  # (their shapes held on the device; an error raised here)
            pending = nxt
            done += len(next(iter(c.values())))
            if progress is not None:
                progress(done, n)
        return [r.result() for r in results] if ahead else results

#: threads that post-process (track) an accelerator's chunks while the next ones compute
POST_THREADS = 4

def evaluate(scene: Scene, values: Mapping[str, Any], outputs: tuple[str, ...] | list[str] = ("statics", "modal"),
             modes: int = 12, rpm=None, chunk: int | None = None, progress: Callable[[int, int], None] | None = None,
             backend: str = "local", dask=None, devices="auto", reference="auto",
             settle_s: float = 1.0) -> dict[str, np.ndarray]:
    """Evaluate a batch of cases with one compiled, vmapped function (in chunks).

    values: {parameter path: (n,) values} (file units, e.g. from :func:`cases`);
    outputs: subset of :data:`OUTPUTS`; modes: frequencies kept per case; rpm: (S,)
    drive-pulley speeds (rpm) of the campbell output; chunk: cases per compiled batch
    (the last one padded; default :func:`default_chunk`); progress: callable(done, total) after each chunk;
    backend: "local" (this process) or "dask" (chunks as tasks on a dask.distributed
    cluster; ``dask`` is a Client, a scheduler address, or None for the
    ``BELTJAX_DASK_SCHEDULER`` address or a LocalCluster of one process per core); settle_s: the
    response's transient (s) where the shooting finds no attracting cycle or the scene settles (the passes
    of orders.fallback_passes, each compiled; beside an accelerator a few on its host: fallback_device);
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
    Failed cases are NaN in every output (unstable ones in the frequencies only); ``flagged``
    (bool, n) marks the cases whose status flags a computed cycle (a span slack in the steady
    cycle, a cycle not settled: :data:`beltjax.orders.FLAGS_KEEPING_NUMBERS`), which keep their
    numbers beside the status, as in ``beltjax orders``.
    """
    require_scene(scene)
    if not isinstance(values, Mapping):
        raise SweepError(f"expected {{parameter path: values}}, got {type(values).__name__}", "values")
    outputs = [outputs] if isinstance(outputs, str) else list(outputs)
    bad = [o for o in outputs if o not in OUTPUTS]
    outputs = tuple(o for o in OUTPUTS if o in outputs)
    if bad or not outputs:
        raise SweepError(f"choose from {', '.join(OUTPUTS)}", "outputs")
    if backend not in ("local", "dask"):
        raise SweepError(f"must be \"local\" or \"dask\", got {backend!r}", "backend")
    try:
        values = {k: np.asarray(v, dtype=float).reshape(-1) for k, v in values.items()}
    except (TypeError, ValueError):
        raise SweepError("every parameter's values must be numbers", "values") from None
    if isinstance(reference, str) and reference != "auto":
        raise SweepError(f'"auto", None or the references of beltjax.sweep_modes.references, got {reference!r}',
                         "reference")
    if not values:
        raise SweepError("no parameters given", "values")
    lengths = {len(v) for v in values.values()}
    if len(lengths) != 1 or 0 in lengths:
        raise SweepError(f"every parameter needs the same, non-zero number of values, got {sorted(lengths)}", "values")
    for k in values:
        try:
            parameters.check(scene, k)
        except parameters.ParameterError as exc:
            raise SweepError(str(exc), "values") from None
    n = lengths.pop()
    if n > MAX_CASES:
        raise SweepError(f"{n} cases, more than the limit {MAX_CASES}", "values")
    scene = drive.canonical(scene)
    rpm = np.zeros(0) if "campbell" not in outputs else np.asarray(rpm, dtype=float).reshape(-1)
    if "campbell" in outputs and rpm.size == 0:
        raise SweepError("the campbell output needs drive-pulley speeds (rpm)", "rpm")
    if "campbell" in outputs:
        validate.speeds(rpm, "rpm", "drive.rpm")
    modes = min(validate.count(modes, "modes"), drive.n_independent(scene))
    chunk = None if chunk is None else validate.count(chunk, "chunk")
    dp = scene.route.order[drive.drive_pulley(scene)]
    moving = float(drive.belt_speed(scene)) != 0.0 or f"pulley.{dp}.speed_rpm" in values
    refs, track = {}, 0
    if reference is not None and ("modal" in outputs or "campbell" in outputs):
        refs = sweep_modes.references(scene, outputs, modes, rpm) if isinstance(reference, str) else dict(reference)
        track = mode_tracking.n_computed(modes, drive.n_independent(scene))
    if "response" in outputs:  # a steady state in crank angle (driven crank, orders, lasting loads)
        from beltjax.orders import OrdersError, Settings, check, fallback_device, fallback_passes, for_scene
        from beltjax.orders.run import check_batched, replaced_by, settle_problem

        if problem := settle_problem(settle_s):
            raise SweepError(problem, "settle_s")

        try:
            check(scene, [max(abs(float(parameters.get_value(scene, f"pulley.{dp}.speed_rpm"))), 1e-9)])
        except OrdersError as exc:
            raise SweepError(str(exc), "outputs") from None
        try:
            check_batched(scene, "a sweep's response output")
        except OrdersError as exc:
            raise SweepError(str(exc), exc.key) from None
    opts = _Options(outputs=outputs, modes=modes, gyro=effects_of(scene).moving_belt and moving, track=track,
                    response=for_scene(scene, Settings(gradients=False)) if "response" in outputs else None)
    post = functools.partial(sweep_modes.track_chunk, refs=refs, modes=modes) if track else (lambda r: r)
    ref = np.asarray(refs["modal"][0].W) if track and refs.get("modal") else None  # projected on the device,
    ref = ref.real if ref is not None and not np.any(ref.imag) else ref  # in real arithmetic where it can be
    pre = _precheck(scene, values, n)
    invalid = pre != _CODE["ok"]
    if invalid.all():
        run_values = values
    else:  # evaluate a valid case in place of invalid ones (their outputs are discarded)
        j = int(np.argmin(invalid))
        run_values = {k: np.where(invalid, v[j], v) for k, v in values.items()}
    run_values = {k: np.broadcast_to(np.asarray(v, float), (n,)) for k, v in full_values(scene, run_values).items()}
    devices = _devices(devices) if backend == "local" else None
    def execute(idx, opts, settle, progress=None, whole=False):  # the cases idx, in chunks of one size (whole: one
        size = idx.size if whole else _chunk_size(idx.size, chunk, rpm.size, devices, drive.n_independent(scene))
        cols = {**run_values, SETTLE_COLUMN: np.full(n, float(settle))} if opts.response else run_values  # chunk)
        chunks = [{k: v[idx][sl] for k, v in cols.items()} for sl in _slices(idx.size, size)]
        if backend == "local":
            results = _run_local(scene, chunks, rpm, opts, size, devices, progress, post, ref)
        else:
            from beltjax.sweep.dask_backend import _run_dask  # imports batch: not at the top

            results = _run_dask(scene, chunks, rpm, opts, size, dask, progress, post, ref)
        return {k: np.concatenate([r[k] for r in results]) for k in results[0]}

    out = execute(np.arange(n), opts, settle_s, progress)
    def unsettled(o):  # the response not reached and no earlier fault (an invalid case ran a valid one)
        return o.pop("response_rerun", False) & np.isin(o["code"], (_CODE["span_slack"], _CODE["not_settled"]))

    rerun = unsettled(out) & ~invalid
    earlier = opts.response.method if opts.response else None  # the method that gave the numbers a pass may replace
    for time_s, method in fallback_passes(opts.response.method, float(settle_s)) if opts.response else []:
        idx = np.flatnonzero(rerun)  # the cases whose periodic state was not reached run again, as in beltjax orders
        if not idx.size:
            break
        host = fallback_device(idx.size) if backend == "local" and devices is None else None  # a few: on the
        with jax.default_device(host) if host is not None else contextlib.nullcontext():  # host's CPU, one batch
            again = execute(idx, dataclasses.replace(opts, response=dataclasses.replace(opts.response, method=method)),
                            time_s, whole=host is not None)
        rerun = np.zeros(n, dtype=bool)
        rerun[idx] = unsettled(again)
        take = replaced_by(again["code"] != _CODE["transient_failed"], earlier == "settle")  # as in beltjax orders
        idx, earlier = idx[take], method
        for k in out:
            out[k][idx] = again[k][take]
    # the checks that need each case's solved installation: the idler where its arm settles, the
    # string-spread limit at the installed tension (validate.solved_status)
    arm = out["tensioner_angle_deg"] if scene.tensioner is not None else None
    solved, _ = validate.solved_status(scene, out["installation_tension_N"], arm, values, n)
    solved_ok = (pre == _CODE["ok"]) & np.isin(out["code"], (_CODE["ok"], _CODE["unstable"], _CODE["span_slack"],
                                                             _CODE["not_settled"]))  # (flagged cases keep numbers)
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
    """Status strings; NaN in every output of a case whose status leaves no state to report
    (frequencies only for unstable ones; a flag on a computed cycle keeps its numbers: the policy of
    :data:`beltjax.orders.FLAGS_KEEPING_NUMBERS`).  pre: (n,) codes of the checks before the
    computation (0: passed)."""
    code = np.where(pre != _CODE["ok"], pre, out.pop("code")).astype(int)
    keeps = np.asarray(out.pop("flag_keeps", False), bool) & (pre == _CODE["ok"]) & (code != _CODE["ok"])
    failed = (code != _CODE["ok"]) & (code != _CODE["unstable"]) & ~keeps
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
    out["flagged"] = np.broadcast_to(keeps, code.shape).copy()  # a flag on a computed cycle, its numbers kept
    return out
