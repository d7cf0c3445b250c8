"""The periodic steady state of a drive at one engine speed, as one pure JAX function (jit, vmap,
grad): the operating point under the mean loads, the periodic state found by shooting
(:mod:`beltjax.orders.shooting`, the default) or by a transient of the scene's excitation until
the start-up has died out, and one recorded excitation cycle reduced to what an engineer reads
against speed (mean, min, max, peak-to-peak, order amplitudes, least slip margin).

A case is the scene with parameter ``values`` set and the drive pulley at ``rpm``; every crank
order of the scene's ``[[fluctuation]]`` follows the speed (its frequency is order x rpm / 60).
The excitation cycle is the least whole number of crank revolutions over which every order
repeats (1 for whole orders, 2 with half orders: :func:`cycle_revolutions`).  Both methods run
the scene's equations (:func:`beltjax.transient.vector_field`) with an adaptive explicit pair
(Dopri8, the rotational model's default; the hybrid model settles with its own implicit fixed
step and measures its settling on the outputs: :class:`Settings`, :func:`_channel_settling`),
and both start on the periodic response of the drive
linearised about the operating point (:mod:`beltjax.orders.linear_start`; ``Settings.start =
"operating_point"`` starts at rest, as a plain transient does).  Shooting then iterates on one
cycle and records the cycle from its fixed point.  The settling transient (``Settings.method =
"settle"``) runs from t = 0 to the end of the recorded cycle, the first whole cycle after
``settle_s``, so that the nonlinear remainder of the start-up dies out.  A second cycle is
recorded at half that time; the largest change of the state between the two, against its range
over the cycle, is the ``settling`` residual (a start-up transient decaying as exp(-s t) leaves
A exp(-s t) at the end and changed by A (exp(-s t/2) - exp(-s t)) between the cycles: once that
change is small against the response, what is left is smaller still whenever s t/2 > ln 2).
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import diffrax
import jax
import jax.numpy as jnp

from beltjax import critical, drive, friction, parameters, runtime, statics
from beltjax.excitation import ADAPTIVE_PERIOD_FRACTION
from beltjax.scene import Scene
from beltjax.drive.couplings import isolator_wind_up
from beltjax.drive import belt_slip
from beltjax.orders import shooting
from beltjax.orders.linear_start import linear_periodic_start
from beltjax.transient import default_dt, default_solver, solver_of, start_vector, vector_field
from beltjax.transient_outputs import UNITS, _outputs_one

#: the transient channels reduced over the cycle (those a scene has; units: transient_outputs.UNITS)
CHANNELS = ("arm_angle_deg", "span_tensions_N", "hub_force_magnitudes_N", "pulley_speeds_rpm", "drive_torques_Nm",
            "spring_moment_Nm", "isolator_moment_Nm", "rotor_speeds_rpm", "decoupler_moments_Nm", "slip_speeds_m_s",
            "friction_power_W", "node_displacements_m")
#: the least swing (channel units) a channel's change counts against in the hybrid model's settling
#: residual (:func:`_channel_settling`): metres and m/s 1e-9, any other unit 1e-6
STILL = {"m": 1e-9, "m/s": 1e-9}
#: the statistics of each channel over the recorded cycle
STATS = ("mean", "min", "max", "p2p")
#: the adaptive solvers a steady state may use
SOLVERS = ("dopri8", "tsit5", "kvaerno5")
#: the fixed-step solvers a hybrid scene may name (:func:`for_scene`)
FIXED_STEP = ("generalized_alpha",)
#: where the settling transient or the shooting may start (:class:`Settings`)
STARTS = ("linear", "operating_point")
#: how the periodic steady state is found (:class:`Settings`)
METHODS = ("shooting", "settle")
#: most crank revolutions of one excitation cycle (orders given to 1/MAX_REVOLUTIONS)
MAX_REVOLUTIONS = 8


@dataclasses.dataclass(frozen=True)
class Settings:
    """Static settings of the compiled steady-state function (hashable).

    samples: output samples per excitation cycle; max_order: highest crank order reported;
    rtol, atol: the adaptive step's tolerances; max_steps: most steps of one case's transient;
    revolutions: crank revolutions per excitation cycle (:func:`cycle_revolutions`); top_order:
    the highest crank order of the excitation (the largest step is a quarter of its period, as
    :data:`beltjax.excitation.ADAPTIVE_PERIOD_FRACTION` in transients); both from the scene by
    :func:`for_scene`; solver: one of
    :data:`SOLVERS` (the explicit Dopri8 by default: on the eight-pulley drive with a decoupler the
    implicit Kvaerno5 took 1.5-3.4x the steps at the same tolerances, and 7x the time); start:
    one of :data:`STARTS`, where the settling transient starts (``"linear"``, the default: the
    linearised drive's periodic response, :mod:`beltjax.orders.linear_start`; ``"operating_point"``:
    the operating point at rest in the rotating frame, as :func:`beltjax.transient.simulate`);
    method: one of :data:`METHODS`, ``"shooting"`` (the default: Newton's method on the one-cycle
    map from that start, :mod:`beltjax.orders.shooting`; :func:`for_scene` makes it ``"settle"``
    for a drive whose state drifts) or ``"settle"`` (a transient of at least ``settle_s``);
    gradients: False where no derivative is taken (a response over speed, a sweep): the shooting
    saves its implicit-function cycle and may stop on Newton's prediction
    (:func:`beltjax.orders.shooting.periodic_orbit`); differentiating such a case raises.
    The hybrid model (:func:`for_scene`, which replaces ``method``, ``solver`` and ``dt``)
    settles with its scene's transient solver
    (``[simulation] solver``, generalized-alpha by default) and, for that fixed-step solver, a step
    of at most ``dt`` (s, the scene's ``dt_s``, default 1e-4) shortened so that every recorded
    sample falls on a step (the solver's outputs between steps are linear interpolations)."""

    samples: int = 128
    max_order: float = 8.0
    rtol: float = 1e-7
    atol: float = 1e-9
    max_steps: int = 1_000_000
    revolutions: int = 1
    solver: str = "dopri8"
    top_order: float = 8.0
    start: str = "linear"
    method: str = "shooting"
    gradients: bool = True
    dt: float | None = None

    @property
    def harmonics(self) -> int:
        """Number of harmonics of the cycle reported (orders k / revolutions, k = 1..harmonics)."""
        return min(int(math.floor(self.max_order * self.revolutions + 1e-9)), self.samples // 2 - 1)

    def orders(self) -> list[float]:
        """The crank orders of the reported harmonics."""
        return [k / self.revolutions for k in range(1, self.harmonics + 1)]


def cycle_revolutions(scene: Scene) -> int:
    """Crank revolutions per excitation cycle: the least n with n x order whole for every order of
    the scene's per-revolution fluctuations (1 without any).  Orders that need more than
    :data:`MAX_REVOLUTIONS` revolutions (or fluctuations at a fixed frequency in Hz, or a trace
    against time) make no cycle in crank angle: the caller refuses or flags them."""
    n = 1
    for f in scene.fluctuations:
        if f.per == "rev":
            q = Fraction(float(f.rate)).limit_denominator(MAX_REVOLUTIONS)
            n = n * q.denominator // math.gcd(n, q.denominator)
    return n


def for_scene(scene: Scene, settings: Settings | None = None) -> Settings:
    """``settings`` (default :class:`Settings`) with the scene's cycle (:func:`cycle_revolutions`)
    and its highest excited crank order (at least 1): static, read from the scene's values."""
    top = max([1.0] + [float(f.rate) for f in scene.fluctuations if f.per == "rev"])
    settings = dataclasses.replace(settings or Settings(), revolutions=cycle_revolutions(scene), top_order=top)
    if belt_slip.n_states(scene):  # creeping pulleys' angles and the slip states drift: no fixed point to shoot for
        settings = dataclasses.replace(settings, method="settle")
    if drive.spans_of(scene).massive:  # the hybrid model: stiff (axial span modes of kHz), its own implicit solver;
        # shooting would carry the variational equations of every span coordinate
        name = default_solver(scene)
        settings = dataclasses.replace(settings, method="settle", solver=name,
                                       dt=default_dt(scene) if name in FIXED_STEP else None)
    return settings


def speed_path(scene: Scene) -> str:
    """The parameter path of the drive pulley's speed (rpm)."""
    return f"pulley.{scene.route.order[drive.drive_pulley(scene)]}.speed_rpm"


def _reduce(x, settings: Settings):
    """Statistics of samples x (K, ...) over one cycle: mean, min, max, p2p and the order amplitudes
    (..., harmonics) (half the peak-to-peak of each harmonic, the channel's units)."""
    K = x.shape[0]
    X = jnp.fft.rfft(x, axis=0)[1 : settings.harmonics + 1]
    amp = 2.0 * jnp.abs(X) / K
    lo, hi = x.min(axis=0), x.max(axis=0)
    return dict(mean=x.mean(axis=0), min=lo, max=hi, p2p=hi - lo, orders=jnp.moveaxis(amp, 0, -1))


def _settling(y_early, y_late, n: int, dt, creeping=None):
    """Largest change of the state between two phase-aligned cycles (K, 2n) dt (s) apart against
    the state's range over the late cycle, for positions and speeds apart (-).  The coordinates
    ``creeping`` (n,) 1.0 / 0.0 (the rotations of free pulleys and rotors with ``belt_slip``) are
    compared after the drift of the late cycle's mean speed over dt: a pulley that creeps turns
    steadily slower than the nominal rolling, and its angle does not repeat."""
    dy = y_late - y_early
    if creeping is not None:
        dy = dy.at[:, :n].add(-creeping * dt * jnp.mean(y_late[:-1, n:], axis=0))
    return shooting.relative_change(dy, y_late, n)


def fixed_step(period, samples: int, dt):
    """The fixed step (s) of a settling transient of ``period`` (s) cycles: at most ``dt`` (s), a
    whole number of steps per sample of the ``samples`` per cycle (numpy or JAX)."""
    return period / (samples * jnp.ceil(period / (samples * dt) - 1e-9))


def settle_cycles(settle_s, period):
    """Whole cycles of ``period`` (s) before the recorded one: at least ``settle_s`` (s) and 2."""
    return jnp.maximum(jnp.ceil(settle_s / period), 2.0)


def _channel_settling(early: dict, late: dict):
    """Largest change of a reported channel (:data:`CHANNELS`, and the hub forces) between two
    phase-aligned cycles (K, ...) against that channel's largest range over the late cycle (-;
    a channel that does not swing against 1e-9 of its size, and at least :data:`STILL` in its
    units: a straight span's transverse displacement is round-off).  The hybrid model's settling
    residual: its state holds the span coordinates' rates, where a free vibration of kHz too small
    to show in any output swings against ranges orders below the bodies' (measured on the
    tensioner bench at 2 elements per span, 2 s from the linear start: 0.13 in the state, 6e-4
    in the channels)."""
    res = jnp.asarray(0.0)
    for name in (*CHANNELS, "hub_forces_N"):
        if name not in late or late[name].size == 0:
            continue
        a, b = early[name], late[name]
        span = jnp.max(b.max(axis=0) - b.min(axis=0))
        least = jnp.maximum(1e-9 * jnp.max(jnp.abs(b)), STILL.get(UNITS[name], 1e-6))
        change = jnp.max(jnp.abs(b - a))
        res = jnp.maximum(res, jnp.where(change > 0, change / jnp.maximum(span, least), 0.0))
    return res


def steady_case(scene: Scene, values: dict, rpm, settle_s, settings: Settings, solved=None) -> dict:
    """The periodic steady state of ``scene`` with ``values`` {path: value} set, drive pulley at
    ``rpm`` (rev/min), by shooting or after at least ``settle_s`` (s) of transient
    (``settings.method``; pure JAX: jit, vmap, grad).
    ``solved``: (q_i, installation, converged) of that scene's operating point at ``rpm`` when
    the caller has it (a sweep's case), else it is solved here.

    Returns: per channel of :data:`CHANNELS` the scene has, ``{channel}:{stat}`` for each of
    :data:`STATS` ((k,) or () in the channel's units) and ``{channel}:orders`` ((k, H) or (H,):
    amplitudes of the orders :meth:`Settings.orders`); ``min_slip_margin`` (per arc with a friction
    coefficient, the least over the cycle, -), ``max_friction_needed`` (per route entry, -);
    ``hub_forces_N`` (K, bearings, 2): the hub force vectors over the cycle (N); ``t_s`` (K,)
    the recorded times (s); ``settling`` (-): :func:`_settling`, or with shooting the recorded
    cycle's own change (:func:`beltjax.orders.shooting.change_over_cycle`; inf where the shooting
    did not converge to an attracting, or without gradients neutral, cycle or its prediction was not
    confirmed: :func:`~beltjax.orders.shooting.prediction_confirmed`); ``shooting_iterations``, ``shooting_cycle_steps``
    (each Newton cycle's steps) and ``floquet_multiplier`` (the cycle's largest, -; 0, zeros and
    nan for a settling transient); ``converged`` (statics), ``overloaded`` (the operating point
    past what a belt carries: :func:`beltjax.statics.operating_faults`) and
    ``solver_ok`` (the transient reached the end) and ``supercritical`` (a span past its critical
    speed at the operating point: :mod:`beltjax.critical`) as 1.0 / 0.0; ``min_span_force_N``: the
    least force of a span on its pulleys over the cycle (N; with ``transport`` its tension less
    rhoA c^2 lam: at or below 0 the belt no longer presses on the pulleys); ``t_end_s`` (the
    recorded cycle's end, s); ``steps`` (all the integrations')."""
    if settings.start not in STARTS:  # over_speed's callers reach here unchecked
        raise ValueError(f"start: {settings.start!r}; choose one of {', '.join(STARTS)}")
    if settings.method not in METHODS:
        raise ValueError(f"method: {settings.method!r}; choose one of {', '.join(METHODS)}")
    path = speed_path(scene)
    sign = jnp.where(parameters.get_value(scene, path) < 0, -1.0, 1.0)  # the scene's sense of rotation
    sc = parameters.set_values(scene, {**values, path: sign * jnp.abs(rpm)})
    v = drive.belt_speed(sc)
    loaded = drive.lasting_loads(sc)
    if solved is None:
        qi, inst, (conv, _, _) = statics.equilibrium(sc, statics.install(sc), speed=v, loaded=loaded)
    else:
        qi, inst, conv = solved
    overloaded = jnp.any(jnp.stack(list(statics.operating_faults(sc, qi, inst).values())))
    torque = drive.drive_torque(qi, sc, inst, v, loaded)
    qi = isolator_wind_up(sc, inst, qi, torque)
    y0 = start_vector(sc, inst, qi, jnp.zeros_like(qi))
    n = qi.shape[0]

    K = settings.samples
    period = settings.revolutions * 60.0 / jnp.abs(rpm)  # s, one excitation cycle
    phase = period * jnp.arange(K + 1) / K
    rm = drive.reduced_mass(sc, inst)  # factored once, for f and for the shooting's f with gradients held
    if settings.method == "shooting" and not settings.gradients:
        sc, inst, rm = shooting.refuse_tangents((sc, inst, rm))
    f = vector_field(sc, inst, rm)
    hybrid = drive.spans_of(sc).massive
    if settings.start == "linear":  # (the hybrid's: the excited orders only, each a dense solve of its 2n states)
        y0 = linear_periodic_start(f, y0, period, K, 2, settings.harmonics) if hybrid else \
            linear_periodic_start(f, y0, period, K)
    term = diffrax.ODETerm(f)
    if settings.solver in FIXED_STEP:  # the hybrid model's implicit fixed step, whole steps per sample
        solver, ctrl = solver_of(dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation,
                                                                                        solver=settings.solver)))
        dt0 = fixed_step(period, K, settings.dt or default_dt(sc))
    else:
        dtmax = ADAPTIVE_PERIOD_FRACTION * 60.0 / (jnp.abs(rpm) * settings.top_order)  # a quarter of the top order's period
        ctrl = diffrax.PIDController(rtol=settings.rtol, atol=settings.atol, dtmax=dtmax)
        solver = {"dopri8": diffrax.Dopri8, "kvaerno5": diffrax.Kvaerno5, "tsit5": diffrax.Tsit5}[settings.solver]()
        dt0 = jnp.minimum(1e-4, period / 64)
    if settings.method == "shooting":  # y0 <- the periodic state, then one cycle from it
        y_orbit, shot = shooting.periodic_orbit(f, vector_field(*shooting.held((sc, inst, rm))), y0, period, phase[:-1],
                                                solver, ctrl, settings.max_steps, n, settings.gradients)
        y0 = jnp.where(shot["ok"] > 0.5, y_orbit, y0)  # no attracting cycle: a cycle from the start (flagged)
        ts = phase
    else:  # a transient of at least settle_s, two cycles recorded
        cycles = settle_cycles(settle_s, period)
        t_late = cycles * period
        t_early = jnp.floor(cycles / 2) * period
        ts = jnp.concatenate([t_early + phase, t_late + phase])
    with runtime.cacheable():  # kept by the persistent compilation cache
        sol = diffrax.diffeqsolve(term, solver, t0=0.0, t1=ts[-1], dt0=dt0, y0=y0,
                                  saveat=diffrax.SaveAt(ts=ts), stepsize_controller=ctrl,
                                  max_steps=settings.max_steps, throw=False)
    ys = sol.ys
    late = ys[-(K + 1) :]  # the recorded cycle (and its end)
    t_rec = ts[-(K + 1) : -1]
    M_full = drive.full_mass_matrix(sc, inst)
    settle_on_channels = hybrid and settings.method == "settle"  # both cycles' outputs: _channel_settling
    rec_t, rec_y = (jnp.concatenate([ts[:K], t_rec]), jnp.concatenate([ys[:K], late[:-1]])) if settle_on_channels \
        else (t_rec, late[:-1])
    chans = jax.vmap(lambda t, y: _outputs_one(t, y, sc, inst, M_full))(rec_t, rec_y)
    free = drive.is_free(sc)
    if "drive_torques_Nm" in chans:
        chans["drive_torques_Nm"] = chans["drive_torques_Nm"][:, [i for i, f in enumerate(free) if not f]]
    if settle_on_channels:
        early = {k: v[:K] for k, v in chans.items()}
        chans = {k: v[K:] for k, v in chans.items()}
    out: dict = {}
    for name in CHANNELS:
        if name not in chans or chans[name].shape[1:] == (0,):
            continue
        for stat, val in _reduce(chans[name], settings).items():
            out[f"{name}:{stat}"] = val
    need, margins = friction.arc_margins(sc, chans["_pulley_forces_N"], chans["_wraps_rad"])
    out["max_friction_needed"] = jnp.max(need, axis=0)
    if margins.shape[-1]:
        out["min_slip_margin"] = jnp.min(margins, axis=0)
    out["hub_forces_N"] = chans["hub_forces_N"]
    out["t_s"] = t_rec
    steps = sol.stats["num_steps"].astype(jnp.float64)
    if settings.method == "shooting":  # the recorded cycle's own change, if the shooting found an attracting cycle
        change = shooting.change_over_cycle(late[0, : 2 * n], late[-1, : 2 * n], late[:-1, : 2 * n], n,
                                            settings.rtol, settings.atol)
        confirmed = shooting.prediction_confirmed(change, shot["multiplier"], shot["predicted"])
        out["settling"] = jnp.where((shot["ok"] > 0.5) & confirmed, change, jnp.inf)
        out["shooting_iterations"], out["floquet_multiplier"] = shot["iterations"], shot["multiplier"]
        out["shooting_cycle_steps"] = shot["cycle_steps"]
        steps = steps + shot["steps"]
    else:
        creeping = None
        if belt_slip.n_states(sc):  # the slip states drift, and so do the creeping pulleys' angles
            creeping = jnp.zeros(n).at[: belt_slip.rotations(sc)].set(1.0)
        out["settling"] = _channel_settling(early, chans) if settle_on_channels else \
            _settling(ys[: K + 1, : 2 * n], late[:, : 2 * n], n, t_late - t_early, creeping)
        out["shooting_iterations"], out["floquet_multiplier"] = jnp.asarray(0.0), jnp.asarray(jnp.nan)
        out["shooting_cycle_steps"] = jnp.zeros(shooting.MAX_ITERATIONS)
    out["converged"] = conv
    out["supercritical"] = critical.supercritical(sc, qi, inst, v).astype(jnp.float64)
    out["overloaded"] = overloaded.astype(jnp.float64)
    out["solver_ok"] = (sol.result == diffrax.RESULTS.successful).astype(jnp.float64)
    out["t_end_s"] = ts[-1]
    out["steps"] = steps
    out["min_span_force_N"] = jnp.min(chans["span_forces_N"])  # with transport, tension less rhoA c^2 lam
    return out
