"""Transients of whole drives with diffrax, for both fidelities (thesis ch. 4 and 7).

The equations are the reduced ones of :func:`beltjax.drive.reduced_system` with time:
``M_ii(q_i, t) q_i'' = F_ii(q_i, q_i', t)`` from the kinematic map ``q = Phi(q_i, t)``
(pulleys rolling with the belt's travel, prescribed by a driven drive pulley or, when no
pulley is driven, that of the free drive pulley, whose rate is then the transport speed:
:func:`beltjax.drive.travel_follows_drive`; the drive pulley's speed fluctuation,
unbalanced centres of mass), the listed effects (transport, gravity,
damping of belt, bearings and tensioner) and the loads of the scene ([[torque]],
[[span_load]]).  The hybrid (ANCF) and rotational (Newton-Euler) fidelities go
through the same map and the same code; the rotational model has only the rigid
coordinates (its spans are massless springs and dampers).

The state is ``y = (q_i, q_i')``; diffrax integrates ``y' = (q_i', M_ii^-1 F_ii)``.
Solvers (``[simulation] solver``): ``generalized_alpha`` (the fixed-step
structural integrator of :mod:`beltjax.integrators`, implicit, second order,
numerical damping of unresolved modes set by ``rho_inf``; the default of the
hybrid model), ``tsit5`` and ``dopri8`` (explicit, adaptive; ``dopri8`` is the
default of the rotational model), ``kvaerno5`` (implicit, adaptive): see
:func:`default_solver`.
The run starts from the static equilibrium at the initial belt speed, changed
by the scene's ``[initial]`` table.  A solver failure raises
:class:`TransientError`; it is never returned as a result.

Outputs, at every ``output_dt_s`` (s): span tensions (elastic, N) and span
forces on the pulleys (tension minus rhoA c^2 lam with ``transport``, N), bearing
forces (the force each pulley, and the tensioner arm at its pivot, puts on its
bearing, N: belt forces, weight and the body's inertia), pulley speeds (rpm) and
rotations from their rolling with the belt (deg), arm angle (deg), spring moment (N m), the torque
that holds each driven pulley on its prescribed motion (N m), and the normal
displacement of chosen span nodes from the installed span line (m).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import drive, excitation, runtime, signals, statics, validate
from beltjax.drive import belt_slip, couplings
from beltjax.span_flags import check_initial_strain, displaced_span_ends, overstretched_spans, run_warnings, slack_spans, slack_warning, slipping_pulleys, supercritical_spans  # noqa: F401
from beltjax.errors import BeltjaxError
from beltjax.integrators import GeneralizedAlpha
from beltjax.scene import Initial, Scene
from beltjax.transient_outputs import UNITS, _columns, _outputs, _outputs_one, friction_channels, output_nodes  # noqa: F401

__all__ = ["TransientError", "SimulationResult", "simulate", "initial_state", "default_dt", "default_solver",
           "slack_spans", "slack_warning", "supercritical_spans", "run_warnings"]


class TransientError(BeltjaxError):
    """A transient that cannot be run or whose solver failed (one-line message)."""


# --------------------------------------------------------------------------- set-up

#: generalized-alpha Newton matrix kept for this many steps (refreshed at once if it fails)
JACOBIAN_EVERY = 200
#: most output samples of one run (memory: every channel is kept)
MAX_OUTPUT_SAMPLES = 2_000_000
#: most time steps of one fixed-step run (t_end / dt): a minute of the rotational model (about
#: 3 us a step), hours of the hybrid one (0.25-0.65 ms a step with 8-16 elements per span:
#: benchmarks/README.md, simulate() table)
MAX_STEPS = 20_000_000
#: Newton tolerance of the implicit steps: relative to max|y|, and absolute (units of y)
NEWTON_RTOL, NEWTON_ATOL = 1e-9, 1e-9


def default_dt(scene: Scene) -> float:
    """Default time step (s): 1e-4 (resolves the response to 1 kHz), or the scene's dt_s."""
    return scene.simulation.dt_s if scene.simulation.dt_s is not None else 1e-4


def default_output_dt(scene: Scene) -> float:
    """Default output interval (s): 5e-4 for the hybrid model (spectra to 1 kHz), 1e-3 rotational."""
    if scene.simulation.output_dt_s is not None:
        return scene.simulation.output_dt_s
    return max(drive.spans_of(scene).default_output_dt, default_dt(scene))


def _rigid_index(scene: Scene) -> dict[str, int]:
    """Position in q_i of each free route entry's rotation, and of the arm ("arm")."""
    idx, k = {}, 0
    for name, free in zip(scene.route.order, drive.is_free(scene)):
        if free:
            idx[name] = k
            k += 1
    if scene.tensioner is not None:
        idx["arm"] = k + len(scene.decouplers)  # after the decouplers' rotors
    return idx


def _straighten(qi_new, qi_old, scene: Scene, inst) -> jax.Array:
    """Spans of qi_new moved so that each stays straight between its (moved) end nodes."""
    spans = drive.spans_of(scene)
    if spans.independent == 0:  # bars: nothing between the end nodes to move
        return qi_new
    # the transient's map at t = 0 (a free drive pulley's rotation moves the belt with it)
    Ea, _ = drive.split_full(drive.full_coordinates(qi_old, scene, inst, t=0.0), scene)
    Eb, _ = drive.split_full(drive.full_coordinates(qi_new, scene, inst, t=0.0), scene)
    d0 = Eb[:, 0:2] - Ea[:, 0:2]
    d1 = Eb[:, -4:-2] - Ea[:, -4:-2]
    Lspan = drive.element_length(scene, inst) * spans.elements
    return qi_new.at[drive.n_rigid(scene):].add(spans.straight_shift(d0, d1, Lspan))


def initial_state(scene: Scene):
    """(installation, q_i(0), q_i'(0)): the steady state at the initial belt speed with the
    ``[initial]`` changes (added pulley rotations, arm angle); spans straight between their
    moved ends.  When the drive pulley's motion is prescribed, the steady state is the
    operating point of the loads acting at t = 0 (each [[torque]] on at t = 0 with its mean, the
    listed bearing drag: :func:`beltjax.drive.mean_body_loads`), so a drive run under steady
    loads starts in its steady motion (an isolated crank's rim lagging its hub by the drive
    torque over the isolator's stiffness); a drive turned by a torque has none, and starts
    unloaded.  Raises StaticsError (one line) when the drive has no equilibrium."""
    torque_driven = drive.travel_follows_drive(scene) and scene.isolator is None
    # statics needs none of the transient tables: the statics view (the loads acting at t = 0)
    # has the structure of the scene's own statics, so that both share one compilation
    bare = drive.statics_scene(scene, at_t=0.0)
    if torque_driven:
        bare = dataclasses.replace(bare, torques=tuple(
            dataclasses.replace(load, mean_Nm=0.0 * load.mean_Nm) for load in bare.torques))
    st = statics.analyse_statics(bare, speed=float(drive.belt_speed(scene)), allow_supercritical=True,
                                 with_unloaded=False)
    inst = st.inst
    qi0 = couplings.isolator_wind_up(scene, inst, jnp.asarray(st.qi), st.drive_torque_Nm)
    ini = scene.initial
    if ini.rotation_deg or ini.arm_angle_deg is not None:
        idx = _rigid_index(scene)
        qi = qi0
        for name, deg in ini.rotation_deg:
            qi = qi.at[idx[name]].add(math.radians(deg))
        if ini.arm_angle_deg is not None:
            qi = qi.at[idx["arm"]].set(math.radians(ini.arm_angle_deg) - inst.arm_angle)
        qi0 = _straighten(check_initial_strain(qi, scene, inst), qi0, scene, inst)
    return inst, qi0, jnp.zeros_like(qi0)


# --------------------------------------------------------------------------- equations


def vector_field(scene: Scene, inst, rm=None):
    """f(t, y, args) of y = (q_i, q_i', slip states: :func:`beltjax.drive.belt_slip.split_state`) for
    diffrax.ODETerm (m, rad, m/s, rad/s per s); ``rm``: :func:`beltjax.drive.reduced_mass`, if had."""
    rm = drive.reduced_mass(scene, inst) if rm is None else rm  # the constant span block of M_ii, factored once

    def f(t, y, args):
        del args
        return _rate(t, y, scene, inst, rm)

    return f


@eqx.filter_jit
def _rate(t, y, scene: Scene, inst, rm):
    """y' of :func:`vector_field`.  Jitted on its own so that a solver's many calls of it (a
    Runge-Kutta method's stages, an implicit step's residual and Jacobian) trace the drive's
    equations once per compilation and reuse the traced program (XLA inlines it): measured, the
    chunk function's tracing fell from 8.3 to 0.9 s on the hybrid tensioner bench
    (4.6 to 0.8 s on its rotational model), the run unchanged."""
    qi, qd, z = belt_slip.split_state(y, drive.n_independent(scene))
    if z.size == 0:
        return jnp.concatenate([qd, drive.reduced_accelerations(qi, qd, scene, inst, rm, t=t)])
    return jnp.concatenate([qd, *drive.reduced_accelerations(qi, qd, scene, inst, rm, t=t, slip=z)])


def start_vector(scene: Scene, inst, qi0, qd0):
    """The transient's initial state y(0) from q_i(0), q_i'(0): the belt has not slid; with
    ``belt_slip`` the pulleys run at their steady creep (:func:`beltjax.drive.belt_slip.creep_start`)."""
    qd0 = belt_slip.creep_start(scene, inst, qi0, qd0)
    return jnp.concatenate([qi0, qd0, belt_slip.initial(scene, qi0.dtype)])


def default_solver(scene: Scene) -> str:
    """The solver used when ``[simulation] solver`` is not given, chosen by measurement
    (benchmarks/bench_transient.py, benchmarks/README.md section 4): ``dopri8`` for the
    rotational fidelity (a few smooth, non-stiff coordinates: at equal accuracy the explicit
    8th-order pair takes far fewer evaluations than a second-order implicit step, whose phase
    error on the 499 Hz arm mode of the tensioner bench is 51 % after 0.5 s at dt = 1e-4 s),
    ``generalized_alpha`` for the hybrid model (stiff: axial span modes of 1-2 kHz and above)."""
    if scene.simulation.solver is not None:
        return scene.simulation.solver
    return drive.spans_of(scene).default_solver


def solver_of(scene: Scene, dtmax=None):
    """(diffrax solver, step-size controller) of ``scene``'s ``[simulation] solver`` (set; dtmax: largest adaptive step, s)."""
    sim = scene.simulation
    name = sim.solver
    if name == "generalized_alpha":
        solver = GeneralizedAlpha(
            rho_inf=sim.rho_inf, full_newton=False, jacobian_every=JACOBIAN_EVERY, newton_iterations=12,
            rtol=NEWTON_RTOL, atol=NEWTON_ATOL,
        )
        return solver, diffrax.ConstantStepSize()
    ctrl = diffrax.PIDController(rtol=sim.rtol, atol=sim.atol, dtmax=dtmax)
    jumps = excitation.jump_times(scene)  # the load windows' edges: stopped at, never stepped over
    if jumps is not None:
        ctrl = diffrax.ClipStepSizeController(ctrl, jump_ts=jumps)
    if name == "tsit5":
        return diffrax.Tsit5(), ctrl
    if name == "dopri8":
        return diffrax.Dopri8(), ctrl
    if name == "kvaerno5":
        return diffrax.Kvaerno5(), ctrl
    raise TransientError(f"simulation.solver: unknown solver {name!r}")


def _start_states(term, solver, controller, y0, t0, dt0):
    """(solver state, controller state, made_jump) at a run's start (t0, first step dt0, s): zeros and
    made_jump True, so the first step evaluates the state at t0 and this program holds no vector field
    (12 s -> 0.1 s of compile, hybrid drive); arrays (a Python bool would recompile the second chunk)."""
    _, c_state = controller.init(term, t0, t0 + dt0, y0, dt0, None, solver.func, solver.error_order(term))
    shapes = jax.eval_shape(lambda y: solver.init(term, t0, t0 + dt0, y, None), y0)
    s_state = jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)
    return jax.tree_util.tree_map(jnp.asarray, (s_state, c_state, True))


def _solve_chunk(term, solver, controller, y0, ts, dt0, max_steps: int, states):
    """``diffrax.diffeqsolve`` from ts[0] to ts[-1], saving at ts, first step dt0 (s), going on
    from ``states`` of the previous chunk (or :func:`_start_states`), so that a run does not
    depend on where it is cut into chunks.

    Returns (ys, result code, steps, accepted steps, the states at ts[-1])."""
    s_state, c_state, jump = states
    sol = diffrax.diffeqsolve(
        term,
        solver,
        t0=ts[0],
        t1=ts[-1],
        dt0=dt0,
        y0=y0,
        saveat=diffrax.SaveAt(ts=ts, solver_state=True, controller_state=True, made_jump=True),
        stepsize_controller=controller,
        max_steps=max_steps,
        solver_state=s_state,
        controller_state=c_state,
        made_jump=jump,
        throw=False,
    )
    states = (sol.solver_state, sol.controller_state, sol.made_jump)
    return sol.ys, sol.result._value, sol.stats["num_steps"], sol.stats["num_accepted_steps"], states


@eqx.filter_jit
def _start(scene: Scene, inst, y0, t0, dt0, dtmax=None):
    """:func:`_start_states` of the scene's solver (:func:`solver_of`; dtmax: largest adaptive step, s)."""
    with runtime.cacheable():
        return _start_states(diffrax.ODETerm(vector_field(scene, inst)), *solver_of(scene, dtmax), y0, t0, dt0)


@eqx.filter_jit
def _integrate_chunk(scene: Scene, inst, y0, ts, dt0, max_steps: int, states, dtmax=None):
    """:func:`_solve_chunk` of the scene's vector field and solver (:func:`solver_of`; dtmax:
    largest adaptive step, s)."""
    with runtime.cacheable():  # kept by the persistent compilation cache: a re-run does not recompile
        return _solve_chunk(diffrax.ODETerm(vector_field(scene, inst)), *solver_of(scene, dtmax), y0, ts, dt0,
                            max_steps, states)


# --------------------------------------------------------------------------- result


@dataclass
class SimulationResult:
    """Time histories of a transient.

    t (nt,) s; channels: name -> array (nt,), (nt, k) or (nt, k, 2) in the units of
    :data:`UNITS`; columns: name -> labels of the k columns; meta: solver, step, steps, wall,
    set-up (statics and the start, before the first chunk) and first-chunk times (s), scene,
    slack_spans (:func:`slack_spans`), supercritical_spans (:func:`supercritical_spans`),
    excitation_warnings (:mod:`beltjax.excitation`); y: the state (nt, 2 n_i) for further use.
    """

    t: np.ndarray
    channels: dict
    columns: dict
    meta: dict
    y: np.ndarray = field(repr=False)

    def summary(self, settle_fraction: float = 0.0) -> dict:
        """JSON-ready summary: per channel and column mean, min, max, peak-to-peak, dominant Hz."""
        chans = {k: v for k, v in self.channels.items() if k != "belt_speed_m_s"}
        return dict(
            meta=self.meta,
            units={k: UNITS[k] for k in chans},
            channels=signals.summarise(self.t, chans, self.columns, settle_fraction=settle_fraction),
        )

    def save_npz(self, path) -> None:
        """Write t, every channel and the column labels to an .npz file."""
        arrays = {"t_s": self.t, **self.channels}
        for k, cols in self.columns.items():
            arrays[f"{k}__columns"] = np.asarray(cols)
        np.savez_compressed(path, **arrays)


_RESULT_MESSAGES = {
    "nonlinear_max_steps_reached": "the implicit (Newton) iteration did not converge",
    "max_steps_reached": "the solver hit max_steps (simulation.max_steps)",
    "dt_min_reached": "the step size collapsed",
    "nonfinite": "the state became non-finite",
}


def _result_name(code: int) -> str:
    for name, val in diffrax.RESULTS._name_to_item.items():
        if int(val._value) == int(code):
            return name
    return f"code {int(code)}"


def simulate(scene: Scene, t_end: float, *, dt: float | None = None, output_dt: float | None = None,
             chunk_s: float | None = None, progress: bool = False) -> SimulationResult:
    """Run a transient of ``scene`` from t = 0 to ``t_end`` (s).

    dt: time step (s; default :func:`default_dt`); output_dt: output interval (s;
    default :func:`default_output_dt`, rounded to a whole number of steps for fixed-step
    solvers, never below the step); chunk_s: the run is integrated in chunks of this length
    (s; default t_end / 10, 0.05 to 1 s) with one compiled function, printing progress to
    stderr when ``progress``; the solver's and step-size controller's states go on from
    chunk to chunk, so the result does not depend on the chunks (to round-off for fixed
    steps).  Raises :class:`TransientError` (one line) for bad arguments (an output interval
    below a fixed step, more than :data:`MAX_STEPS` steps, forcing the step or the output
    sampling cannot resolve: :mod:`beltjax.excitation`) or a failed solver (then with the
    outputs up to the failure as ``exc.partial``, a :class:`SimulationResult` whose meta has
    ``failure``), and StaticsError when the drive has no equilibrium to start from.  Spans that
    go slack or pass the critical speed (:mod:`beltjax.critical`), arcs past their capstan limit
    and hybrid span ends that slid far (:func:`displaced_span_ends`) are recorded in ``meta``
    (slack_spans, supercritical_spans, overstretched_spans, slipping_pulleys, displaced_span_ends), as are
    excitation_warnings; :func:`run_warnings` words them.
    """
    if not (isinstance(t_end, (int, float)) and math.isfinite(t_end) and t_end > 0):
        raise TransientError(f"t_end: must be a finite time > 0 s, got {t_end!r}")
    scene = validate.check_scene(drive.canonical(scene))  # its own keys before the excitation's checks
    if refused := belt_slip.transient_check(scene):
        raise TransientError(f"{refused[0]}: {refused[1]}", refused[0])
    scene = dataclasses.replace(scene, simulation=dataclasses.replace(scene.simulation, solver=default_solver(scene)))
    dt = default_dt(scene) if dt is None else validate.interval(dt, "dt")
    if not (math.isfinite(dt) and 0 < dt < t_end):
        raise TransientError(f"dt: must be > 0 and below t_end = {t_end!r} s, got {dt!r}")
    out_dt = default_output_dt(scene) if output_dt is None else validate.interval(output_dt, "output_dt")
    fixed = scene.simulation.solver == "generalized_alpha"
    if fixed:
        if out_dt < dt * (1 - 1e-9):
            from_scene = output_dt is None and scene.simulation.output_dt_s is not None
            key = "simulation.output_dt_s" if from_scene else "output_dt"
            raise TransientError(
                f"{key}: {out_dt:.4g} s is below the time step dt = {dt:.4g} s of the fixed-step solver "
                f"{scene.simulation.solver}, which gives outputs only at its steps: give an output interval >= dt "
                "(a whole number of steps) or a smaller dt")
        out_dt = max(1, round(out_dt / dt)) * dt
    n_out = int(math.floor(t_end / out_dt + 1e-9))
    if n_out > MAX_OUTPUT_SAMPLES:
        raise TransientError(
            f"t_end / output_dt gives {n_out} output samples, at most {MAX_OUTPUT_SAMPLES}: "
            "shorten the run or raise the output interval"
        )
    if n_out < 1:
        raise TransientError(f"t_end = {t_end!r} s is shorter than the output interval {out_dt:.3g} s")
    forcing = excitation.check(scene, t_end, dt, out_dt, fixed)
    if forcing.refused:
        raise TransientError(forcing.refused[0])
    if fixed and t_end / dt > MAX_STEPS:  # (an adaptive run's steps are bounded by simulation.max_steps)
        raise TransientError(
            f"t_end: {t_end:g} s needs {math.ceil(t_end / dt - 1e-9)} steps of dt = {dt:.3g} s, more than the "
            f"limit of {MAX_STEPS} (about a minute of the rotational model, hours of the hybrid one): shorten the "
            "run or raise dt")
    dtmax = None if forcing.dtmax is None else jnp.asarray(forcing.dtmax)
    chunk_s = max(0.05, min(1.0, t_end / 10)) if chunk_s is None else validate.interval(chunk_s, "chunk_s")
    per_chunk = max(1, int(round(chunk_s / out_dt)))
    n_chunks = -(-n_out // per_chunk)
    steps_per_chunk = int(math.ceil(per_chunk * out_dt / dt)) + 8
    max_steps = steps_per_chunk if fixed else scene.simulation.max_steps

    wall0 = time.perf_counter()
    from beltjax.progress import Reporter, bar

    reporter = Reporter()  # progress on stderr
    inst, qi0, qd0 = initial_state(scene)
    # the compiled integrator and outputs do not depend on the initial-state table
    scene = dataclasses.replace(scene, initial=Initial())
    y = start_vector(scene, inst, qi0, qd0)
    ts_all, ys_all, steps = [np.zeros(1)], [np.asarray(y)[None]], 0
    compile_s = None
    dt0 = jnp.asarray(dt, dtype=y.dtype)
    t0 = time.perf_counter()
    states = _start(scene, inst, y, jnp.zeros_like(dt0), dt0, dtmax)
    setup_s = time.perf_counter() - wall0  # statics and the integrator's start, before the first chunk
    failure = None
    for c in range(n_chunks):
        k0 = c * per_chunk
        ts = (k0 + np.arange(per_chunk + 1)) * out_dt
        if c:
            t0 = time.perf_counter()
        ys, code, nst, n_ok, states = _integrate_chunk(scene, inst, y, jnp.asarray(ts), dt0, max_steps, states, dtmax)
        code = int(code)
        if not fixed:  # the next chunk's first step: this chunk's mean accepted step
            dt0 = jnp.asarray((ts[-1] - ts[0]) / max(1, int(n_ok)), dtype=y.dtype)
        if compile_s is None:
            compile_s = time.perf_counter() - t0
        ys = np.asarray(ys)
        steps += int(nst)
        if code != 0:
            name = _result_name(code)
            why = _RESULT_MESSAGES.get(name, name)
            if fixed:
                advice = f"try a smaller simulation.dt_s (now {dt:.3g} s)"
            elif name == "max_steps_reached":
                advice = (f"the model may be too stiff for an explicit solver: try simulation.solver = "
                          f'"generalized_alpha", or raise simulation.max_steps (now {max_steps})')
            else:
                advice = f"try a smaller simulation.rtol (now {scene.simulation.rtol:g})"
            failure = f"solver {scene.simulation.solver} failed between t = {ts[0]:.4g} s and {ts[-1]:.4g} s: {why}; {advice}"
        elif not np.all(np.isfinite(ys)):
            failure = f"solver {scene.simulation.solver} produced non-finite states near t = {ts[0]:.4g} s"
        if failure is not None:  # keep what was solved: the samples before the failure
            finite = np.all(np.isfinite(ys), axis=1)  # diffrax fills the save times it did not reach with inf
            solved = len(ys) if finite.all() else int(np.argmin(finite))
            ts_all.append(ts[1:solved])
            ys_all.append(ys[1:solved])
            break
        y = jnp.asarray(ys[-1])
        ts_all.append(ts[1:])
        ys_all.append(ys[1:])
        if progress:
            done = min(ts[-1], t_end)
            el = time.perf_counter() - wall0
            reporter.update(f"  simulate {bar(done / t_end)} t = {done:7.3f} / {t_end:g} s  ({el:6.1f} s)")
    if progress:
        reporter.finish()
    t = np.concatenate(ts_all)
    ys = np.concatenate(ys_all)
    t, ys = t[t <= t_end + 1e-12], ys[t <= t_end + 1e-12]  # (both masks of the t before the assignment)
    run = dict(dt_s=dt, output_dt_s=out_dt, steps=steps, wall_s=time.perf_counter() - wall0, setup_s=setup_s,
               first_chunk_s=compile_s)
    if failure is not None:  # the outputs up to the failure go with the error (``exc.partial``)
        try:
            partial = _result(scene, inst, t, ys, forcing, fixed, dict(run, failure=failure)) if len(t) else None
        except TransientError:  # (outputs that are not finite: none kept, and the message says so)
            partial = None
        exc = TransientError(f"{failure} ({f'outputs up to t = {t[-1]:.4g} s kept' if partial else 'no outputs kept'})")
        exc.partial = partial
        raise exc
    return _result(scene, inst, t, ys, forcing, fixed, run)


def _result(scene: Scene, inst, t, ys, forcing, fixed: bool, run: dict) -> SimulationResult:
    """The :class:`SimulationResult` of the saved states ys at times t (s): the output channels,
    their checks and the meta (``run``: the run's dt_s, output_dt_s, steps, wall and compile times)."""
    dt, out_dt = run["dt_s"], run["output_dt_s"]
    chans = {k: np.asarray(v) for k, v in _outputs(jnp.asarray(t), jnp.asarray(ys), scene, inst).items()}
    pulley_forces, wraps = chans.pop("_pulley_forces_N"), chans.pop("_wraps_rad")
    cols = _columns(scene)
    if not cols["drive_torques_Nm"]:
        chans.pop("drive_torques_Nm")
        cols.pop("drive_torques_Nm")
    else:
        free = drive.is_free(scene)
        chans["drive_torques_Nm"] = chans["drive_torques_Nm"][:, [i for i, f in enumerate(free) if not f]]
    for k, v in chans.items():
        if not np.all(np.isfinite(v)):
            raise TransientError(f"output {k} is not finite: the run diverged")
    slides = chans.pop("_end_slides_m", None)
    slipping = friction_channels(scene, wraps, pulley_forces, t, chans, cols)
    meta = dict(
        fidelity=scene.model.fidelity,
        elements_per_span=drive.spans_of(scene).independent // 4,
        effects=list(scene.model.effects),
        n_independent=drive.n_independent(scene),
        solver=scene.simulation.solver,
        dt_s=dt,
        rho_inf=scene.simulation.rho_inf if fixed else None,
        output_dt_s=out_dt,
        t_end_s=float(t[-1]),
        steps=run["steps"],
        wall_s=run["wall_s"],
        setup_s=run["setup_s"],
        first_chunk_s=run["first_chunk_s"],
        installation_tension_N=float(inst.tension),
        slack_spans=slack_spans(t, T := chans["span_tensions_N"], cols["span_tensions_N"]),
        supercritical_spans=supercritical_spans(t, pulley_forces, cols["span_forces_N"], chans["belt_speed_m_s"], T),
        overstretched_spans=overstretched_spans(t, T, float(scene.belt.EA), cols["span_tensions_N"]),
        slipping_pulleys=slipping,
        displaced_span_ends=[] if slides is None else displaced_span_ends(t, slides, np.asarray(inst.span_length), cols["span_tensions_N"]),
        excitation_warnings=[*forcing.warnings,
                             *excitation.after_run(scene, chans["pulley_speeds_rpm"], dt, out_dt, fixed)],
    )
    if "failure" in run:
        meta["failure"] = run["failure"]
    return SimulationResult(t=t, channels=chans, columns=cols, meta=meta, y=ys)

