"""Forcing that a transient's time step and output sampling must resolve.

A harmonic forcing sampled by too coarse a step is not smoothed away but *aliased*: the
implicit midpoint rule evaluates a 4990 Hz torque once per step of 2e-4 s (5000 samples per
second), where it is indistinguishable from a 10 Hz torque, and the drive answers that
false 10 Hz excitation with a large, entirely wrong response.  The same holds for the
outputs: a response at a frequency above half the output rate shows up in the saved
histories and their spectra at a false, lower frequency.

:func:`forcing` lists a scene's excitations within a run of ``t_end`` s:

* each ``[[torque]]`` and ``[[span_load]]`` with an amplitude and ``frequency_hz`` > 0 that
  acts before the run ends;
* the drive pulley's speed fluctuation (``fluctuation_frequency_hz``, with the
  ``speed_fluctuation`` effect) and each ``[[fluctuation]]`` harmonic (an order at the run's
  highest drive speed);
* the rotation of each unbalanced pulley (``cm_offset``, with the ``unbalance`` effect): once
  per revolution, at the highest speed the pulley reaches in the run (the run-up's end or
  target speed, plus the fluctuation's peak speed; a free drive pulley at its initial
  speed, and the recorded speeds are checked again after the run: :func:`after_run`);
* load windows (``t_start_s`` to ``t_end_s``, both inside the run) as pulses of their length.

:func:`check` then, before anything is compiled:

* fixed-step solvers (generalized-alpha, step dt): refuses a harmonic forcing at or above the
  step's Nyquist frequency ``1 / (2 dt)`` and a load window shorter than
  :data:`MIN_WINDOW_STEPS` steps; warns below :data:`MIN_STEPS_PER_PERIOD` steps per period
  (or :data:`WARN_WINDOW_STEPS` steps per window);
* every solver: refuses a harmonic forcing at or above the outputs' Nyquist frequency
  ``1 / (2 output_dt)``, naming the output interval needed;
* adaptive solvers: gives the largest step (``dtmax``, s) that keeps the step-size controller
  from stepping over a harmonic forcing (a quarter of its shortest period), and
  :func:`jump_times` are the load windows' edges, where the controller must stop (else,
  from a quiet drive, a step of 10 ms steps over a 0.2 ms torque pulse as if it were not
  there: tests/test_excitation.py).

Accuracy of generalized-alpha on a forced oscillator (``benchmarks/bench_forcing_resolution.py``:
x'' + 2 zeta w_max x' + w0^2 x = sin(w t), zeta = 0.1, steady state, rho_inf 0.9 and 1):
the amplitude of the response is off by 1.6 % (mass-controlled, w0 = 0) to 3.5 %
(w0 = w / 2) at 10 steps per forcing period, 0.4 % to 0.9 % at 20 (second order:
about 160 / n^2 to 350 / n^2 %), and by 13 % at 10, 3.3 % at 20 steps near a resonance
(w0 = 0.9 w); the phase lags by 0.4-0.8 deg at 10 steps (8 deg near the resonance).  Hence
the warning below 20 steps per period.  At 1.002 steps per period the same oscillator
answers the alias at f / 500 with 3 to 2550 times the true amplitude: hence the refusal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np

from beltjax import drive
from beltjax.scene import Scene
from beltjax.drive.effects import effects_of

#: fewer steps of a fixed-step solver per forcing period than this give a warning
MIN_STEPS_PER_PERIOD = 20
#: a load window shorter than this many fixed steps is refused (the step may miss it or take it whole)
MIN_WINDOW_STEPS = 2
#: a load window shorter than this many fixed steps gives a warning (its impulse is resolved to 1 / n)
WARN_WINDOW_STEPS = 10
#: largest adaptive step: this fraction of the shortest forcing period
ADAPTIVE_PERIOD_FRACTION = 0.25


@dataclass(frozen=True)
class Forcing:
    """One excitation of a run: key (scene key path), what (words), frequency_hz (Hz, harmonic
    forcing) or window_s (s, a load window: a pulse of that length)."""

    key: str
    what: str
    frequency_hz: float | None = None
    window_s: float | None = None


@dataclass
class Resolution:
    """Outcome of :func:`check`: refused (one-line messages; the run must not start), warnings
    (records for :func:`warning`), dtmax (s, the largest step of an adaptive solver, or None)."""

    refused: list[str] = field(default_factory=list)
    warnings: list[dict] = field(default_factory=list)
    dtmax: float | None = None


def peak_drive_speed(scene: Scene, t_end: float) -> float:
    """Highest angular speed (rad/s) of the drive pulley's prescribed motion in [0, t_end] s:
    the start or end of the run-up (held at its target speed once reached), plus the speed
    fluctuation's peak 2 pi f A."""
    p = scene.pulley(scene.route.order[drive.drive_pulley(scene)])
    rpm = 2 * math.pi / 60.0
    w0 = abs(float(p.speed_rpm)) * rpm
    a = float(p.acceleration_rpm_per_s) * rpm
    tau = t_end
    if p.target_speed_rpm is not None and a != 0.0:
        tau = min(t_end, max(0.0, (float(p.target_speed_rpm) * rpm - w0) / a))
    w = max(w0, abs(w0 + a * tau))
    if "speed_fluctuation" in effects_of(scene):
        w0 = w
        w += 2 * math.pi * float(p.fluctuation_frequency_hz) * math.radians(abs(float(p.fluctuation_amplitude_deg)))
        for x in scene.fluctuations:  # each harmonic's peak speed: n w A (orders) or 2 pi f A
            rate = float(x.rate) * w0 if x.per == "rev" else 2 * math.pi * float(x.rate)
            w += rate * math.radians(float(np.max(np.abs(np.asarray(x.amplitude_deg)))))  # a table: its largest
    return w


def _window(key: str, what: str, t_start, t_end_load, t_end: float) -> list[Forcing]:
    if t_end_load is None or float(t_end_load) > t_end:
        return []
    return [Forcing(key, what, window_s=float(t_end_load) - max(0.0, float(t_start)))]


def forcing(scene: Scene, t_end: float) -> list[Forcing]:
    """The excitations of ``scene`` in a run from 0 to ``t_end`` s (see the module docstring)."""
    out: list[Forcing] = []
    for i, ld in enumerate(scene.torques):
        if float(ld.t_start_s) >= t_end or (float(ld.mean_Nm) == 0.0 and float(ld.amplitude_Nm) == 0.0):
            continue
        what = f"the torque on {ld.pulley}"
        if float(ld.amplitude_Nm) != 0.0 and float(ld.frequency_hz) > 0.0:
            out.append(Forcing(f"torque[{i}].frequency_hz", what, frequency_hz=float(ld.frequency_hz)))
        out += _window(f"torque[{i}].t_end_s", what, ld.t_start_s, ld.t_end_s, t_end)
    for i, ld in enumerate(scene.span_loads):
        if float(ld.t_start_s) >= t_end or float(ld.amplitude_N) == 0.0:
            continue
        what = f"the load on span {ld.span}"
        if float(ld.frequency_hz) > 0.0:
            out.append(Forcing(f"span_load[{i}].frequency_hz", what, frequency_hz=float(ld.frequency_hz)))
        out += _window(f"span_load[{i}].t_end_s", what, ld.t_start_s, ld.t_end_s, t_end)
    d = scene.pulley(scene.route.order[drive.drive_pulley(scene)])
    if ("speed_fluctuation" in effects_of(scene) and float(d.fluctuation_frequency_hz) > 0.0
            and float(d.fluctuation_amplitude_deg) != 0.0):
        out.append(Forcing(f"pulley[{[p.name for p in scene.pulleys].index(d.name)}].fluctuation_frequency_hz",
                           f"the speed fluctuation of {d.name}", frequency_hz=float(d.fluctuation_frequency_hz)))
    if "speed_fluctuation" in effects_of(scene) and scene.fluctuations:
        w = peak_drive_speed(scene, t_end)  # an order's frequency at the highest speed of the run
        for i, x in enumerate(scene.fluctuations):
            if not np.any(np.asarray(x.amplitude_deg) != 0.0):
                continue
            f = float(x.rate) * w / (2 * math.pi) if x.per == "rev" else float(x.rate)
            what = (f"order {float(x.rate):.4g} of the fluctuation of {d.name}" if x.per == "rev"
                    else f"the fluctuation of {d.name} at {float(x.rate):.4g} Hz")
            key = x.file and "file" or ("order" if x.per == "rev" else "frequency_hz")
            out.append(Forcing(f"{x.key or f'fluctuation[{i}]'}.{key}", what, frequency_hz=f))
    if "unbalance" in effects_of(scene):
        v = peak_drive_speed(scene, t_end) * float(d.radius)  # belt speed, m/s
        for i, p in enumerate(scene.pulleys):
            if p.name in scene.route.order and np.any(np.asarray(p.cm_offset) != 0.0) and v > 0.0:
                f = v / float(p.radius) / (2 * math.pi)
                out.append(Forcing(f"pulley[{i}].cm_offset",
                                   f"the unbalance of {p.name} (once per revolution, up to {60 * f:.5g} rpm)",
                                   frequency_hz=f))
    return out


def _alias(f: float, rate: float) -> float:
    """Frequency (Hz) at which f (Hz) appears when sampled ``rate`` times a second."""
    return abs(f - rate * round(f / rate))


def _error_range(n: float) -> str:
    """The measured amplitude error of generalized-alpha at n steps per period (module docstring)."""
    return f"{1.6 * (10 / n) ** 2:.2g}-{3.5 * (10 / n) ** 2:.2g} %"


def check(scene: Scene, t_end: float, dt: float, output_dt: float, fixed: bool) -> Resolution:
    """Refusals, warnings and the adaptive dtmax (s) for a run of ``t_end`` s at step ``dt`` s
    (``fixed``: a fixed-step solver; else dt is only the first step) saving every
    ``output_dt`` s; see the module docstring."""
    res = Resolution()
    limits: list[float] = []
    for fc in forcing(scene, t_end):
        if fc.frequency_hz is not None:
            f = fc.frequency_hz
            n = 1.0 / (f * dt)  # steps per period
            if fixed and n <= 2.0:
                res.refused.append(
                    f"{fc.key}: {fc.what} at {f:.6g} Hz is at or above the Nyquist frequency {0.5 / dt:.6g} Hz of the "
                    f"time step dt = {dt:.3g} s: the step would sample it as a false {_alias(f, 1 / dt):.4g} Hz "
                    f"excitation; give dt <= {1 / (MIN_STEPS_PER_PERIOD * f):.3g} s ({MIN_STEPS_PER_PERIOD} steps per "
                    "period) or remove the forcing")
                continue
            if f * output_dt >= 0.5:
                need = 0.5 / f
                hint = f"an output interval below {need:.4g} s"
                if fixed:
                    k = math.ceil(need / dt - 1e-9) - 1
                    hint += f" (a whole number of steps: {k * dt:.4g} s)"
                res.refused.append(
                    f"{fc.key}: {fc.what} at {f:.6g} Hz is at or above the Nyquist frequency {0.5 / output_dt:.6g} Hz "
                    f"of the output interval output_dt = {output_dt:.3g} s: it would show in the outputs as a false "
                    f"{_alias(f, 1 / output_dt):.4g} Hz response; give {hint}")
                continue
            if fixed and n < MIN_STEPS_PER_PERIOD:
                res.warnings.append(dict(key=fc.key, what=fc.what, frequency_hz=f, steps=n, dt_s=dt))
            limits.append(ADAPTIVE_PERIOD_FRACTION / f)
        else:
            w = fc.window_s
            n = w / dt
            if fixed and n < MIN_WINDOW_STEPS:
                res.refused.append(
                    f"{fc.key}: {fc.what} acts for {w:.3g} s (t_start_s to t_end_s), less than {MIN_WINDOW_STEPS} time "
                    f"steps (dt = {dt:.3g} s): the step may miss it or take it whole; give dt <= "
                    f"{w / WARN_WINDOW_STEPS:.3g} s ({WARN_WINDOW_STEPS} steps) or a longer window")
                continue
            if fixed and n < WARN_WINDOW_STEPS:
                res.warnings.append(dict(key=fc.key, what=fc.what, window_s=w, steps=n, dt_s=dt))
    if not fixed and limits:
        res.dtmax = min(limits)
    return res


def jump_times(scene: Scene):
    """The start and end times (s) of every load's window, as an array for an adaptive
    step-size controller's ``jump_ts`` (pure: traced under jit), or None without loads."""
    ts = [t for ld in (*scene.torques, *scene.span_loads) for t in (ld.t_start_s, ld.t_end_s) if t is not None]
    return jnp.stack([jnp.asarray(t, dtype=float) for t in ts]) if ts else None


def after_run(scene: Scene, speeds_rpm, dt: float, output_dt: float, fixed: bool) -> list[dict]:
    """Warning records for unbalanced pulleys that turned faster in the run than resolved.

    speeds_rpm: (nt, n) recorded pulley speeds (route order).  A free drive pulley's speed is
    not known before the run (:func:`forcing` takes its initial speed), so its once-per-revolution
    force is checked here against the step (fixed-step solvers) and the output sampling.
    """
    if "unbalance" not in effects_of(scene):
        return []
    out = []
    limit = min(0.5 / output_dt, 0.5 / dt if fixed else math.inf)
    for i, p in enumerate(scene.pulleys):
        if p.name not in scene.route.order or not np.any(np.asarray(p.cm_offset) != 0.0):
            continue
        f = float(np.max(np.abs(np.asarray(speeds_rpm)[:, scene.route.order.index(p.name)]))) / 60.0
        if f >= limit:
            out.append(dict(key=f"pulley[{i}].cm_offset",
                            what=f"the unbalance of {p.name} (once per revolution, up to {60 * f:.5g} rpm)",
                            frequency_hz=f, nyquist_hz=limit, dt_s=dt))
    return out


def warning(record: dict) -> str:
    """One line from a warning record of :func:`check` or :func:`after_run`."""
    key, what, dt = record["key"], record["what"], record["dt_s"]
    if "nyquist_hz" in record:
        return (f"warning: {key}: {what} reached {record['frequency_hz']:.6g} Hz in the run, at or above the Nyquist "
                f"frequency {record['nyquist_hz']:.6g} Hz of the step or the outputs: its force is aliased there, so "
                "the results at that frequency are not physical")
    n = record["steps"]
    if "window_s" in record:
        return (f"warning: {key}: {what} acts for {record['window_s']:.3g} s, only {n:.3g} time steps of dt = {dt:.3g} "
                f"s: its impulse is resolved to about 1/{max(1, round(n))}; give dt <= "
                f"{record['window_s'] / WARN_WINDOW_STEPS:.3g} s for {WARN_WINDOW_STEPS} steps")
    f = record["frequency_hz"]
    return (f"warning: {key}: {what} at {f:.6g} Hz has only {n:.3g} time steps of dt = {dt:.3g} s per period "
            f"(fewer than {MIN_STEPS_PER_PERIOD}): generalized-alpha's response to it is off by about "
            f"{_error_range(n)} in amplitude (more near a resonance); give dt <= "
            f"{1 / (MIN_STEPS_PER_PERIOD * f):.3g} s")
