"""The ``[[fluctuation]]`` tables of a scene: the drive pulley's angle fluctuation as any list of
orders (or fixed frequencies), or a measured speed trace read into orders.

Each table is one harmonic of the driven drive pulley's angle (the ``speed_fluctuation`` effect)::

    [[fluctuation]]
    pulley = "crank"
    order = 2.0            # cycles per revolution (it follows the speed in run-ups), or
    # frequency_hz = 30.0  #   a fixed frequency (Hz)
    amplitude_deg = 0.6    # deg
    phase_deg = 0.0        # deg, at the start of the run

The amplitude may be a table against the pulley's nominal speed (an engine's fluctuation falls as
it speeds up), interpolated linearly and held beyond its ends::

    rpm = [800.0, 2000.0, 4000.0, 6000.0]     # increasing, > 0
    amplitude_deg = [0.5, 0.12, 0.03, 0.015]   # one per speed

or a measured trace of one cycle, repeated (the harmonics of its Fourier series)::

    [[fluctuation]]
    pulley = "crank"
    file = "crank_speed.csv"   # columns angle_deg (crank angle) or time_s, and speed_rpm; the
                               #   last sample closes the cycle (its angle or time is the first's
                               #   plus one cycle)
    harmonics = 24             # harmonics of the cycle kept (default 24)

A trace against the crank angle gives orders k 360 / C (C the cycle in degrees: 720 for a
four-stroke engine's two revolutions), with the angle fluctuation's amplitude integrated from
the relative speed (d(delta theta)/d alpha = omega / omega_mean - 1): it scales with the speed, as
orders do.  A trace against time gives frequencies k / T; its mean speed must be the pulley's
``speed_rpm`` (within 2 %).  The cycle starts at the run's start.

The file is named relative to the scene file's folder and lies inside it (no absolute path, no
``..``, no link out of it).  Every row has the header's columns; every sample lies in its column's
range (:data:`COLUMNS`) and every harmonic read from it in the ranges of a hand-written one.
"""

from __future__ import annotations

import math
import os
import pathlib
import re

import numpy as np

from beltjax import schema, textfile
from beltjax.scene.sections import _arr
from beltjax.scene.spec import Fluctuation

KEYS = ("pulley", "order", "frequency_hz", "amplitude_deg", "rpm", "phase_deg", "file", "harmonics")
#: harmonics of a trace kept by default
HARMONICS = 24
#: samples of the uniform grid a trace is resampled to (at least 4 per harmonic)
GRID = 1024
#: a time trace's mean speed must be the pulley's speed to this fraction
SPEED_TOLERANCE = 0.02
#: the accepted range of each column of a trace: speed as ``pulley.speed_rpm``, time as the schema's
#: times; the crank angle ten turns either way (a cycle is one or two turns, 720 deg for a
#: four-stroke engine; a longer one gives orders below 0.05, which no drive has)
COLUMNS = {"speed_rpm": schema.FIELDS["pulley.speed_rpm"], "time_s": schema.FIELDS["torque.t_start_s"],
           "angle_deg": schema.Field("deg", -3600.0, 3600.0, "ten turns either way: a crank cycle is one or two turns")}
#: a trace file's name and header are shown cut to this many characters
NAME_CHARS = 60
_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def parse(data, drive, base: str, table, num, source) -> tuple[Fluctuation, ...]:
    """The scene's fluctuations from the ``[[fluctuation]]`` array ``data``; ``drive`` the drive
    pulley (its name, whether driven, its speed_rpm), ``base`` the folder a trace's file is
    relative to; ``table`` / ``num`` the scene's table and number readers."""
    name, driven, rpm = drive
    out = []
    for i, d in enumerate(data):
        t = table(d, f"fluctuation[{i}]", source, KEYS)
        pulley = t.string("pulley")
        if pulley != name or not driven:
            t.fail("pulley", f"{pulley!r} is not the driven drive pulley (only a prescribed motion fluctuates; "
                   f"here {name!r}{'' if driven else ', not driven'})")
        if t.has("file"):
            for k in ("order", "frequency_hz", "amplitude_deg", "rpm", "phase_deg"):
                if t.has(k):
                    t.fail(k, "a trace (file) gives its own harmonics: leave this key out")
            n = t.integer("harmonics", required=False, default=HARMONICS, minimum=1, maximum=GRID // 4)
            out += _trace(t, pulley, base, n, rpm, f"fluctuation[{i}]")
            continue
        if t.has("harmonics"):
            t.fail("harmonics", "only a trace (file) has harmonics")
        if t.has("order") == t.has("frequency_hz"):
            t.fail("order", "give exactly one of order (cycles per revolution) and frequency_hz")
        per = "rev" if t.has("order") else "s"
        rate = num(t, "order" if per == "rev" else "frequency_hz", "fluctuation")
        if rate <= 0:
            t.fail("order" if per == "rev" else "frequency_hz", f"must be > 0, got {rate!r}")
        amp, speeds = _amplitude(t, num)
        out.append(Fluctuation(pulley=pulley, per=per, rate=_arr(rate), amplitude_deg=amp,
                               phase_deg=_arr(num(t, "phase_deg", "fluctuation", required=False)),
                               key=f"fluctuation[{i}]", rpm=speeds))
    return tuple(out)


def _amplitude(t, num):
    """(amplitude_deg, rpm): a number and None, or with ``rpm`` two arrays of one length >= 2 (the
    speeds increasing and > 0, each amplitude in the field's range)."""
    if not t.has("rpm"):
        if isinstance(t.raw("amplitude_deg", False), list):
            t.fail("amplitude_deg", "an array of amplitudes needs rpm = [...], the speeds they are given at")
        return _arr(num(t, "amplitude_deg", "fluctuation")), None
    speeds, amps = t.raw("rpm", True), t.raw("amplitude_deg", True)
    for k, v in (("rpm", speeds), ("amplitude_deg", amps)):
        if not isinstance(v, list) or len(v) < 2:
            t.fail(k, "expected an array of at least two numbers (amplitude_deg one per speed of rpm)")
    if len(speeds) != len(amps):
        t.fail("amplitude_deg", f"{len(amps)} amplitudes for {len(speeds)} speeds of rpm: give one per speed")
    r = t.reader
    speeds = [r.number(t.path("rpm"), v, positive=True) for v in speeds]
    amps = [r.number(t.path("amplitude_deg"), v, nonnegative=True) for v in amps]
    for a in amps:
        msg = schema.problem(schema.FIELDS["fluctuation.amplitude_deg"], a)
        if msg:
            t.fail("amplitude_deg", msg)
    for s in speeds:
        msg = schema.problem(schema.FIELDS["pulley.speed_rpm"], s)
        if msg:
            t.fail("rpm", msg)
    if any(b <= a for a, b in zip(speeds, speeds[1:])):
        t.fail("rpm", "the speeds must increase")
    return _arr(amps), _arr(speeds)


def _trace_file(t, base: str) -> tuple[str, str]:
    """(path, name as messages show it) of a trace's ``file``: a path relative to ``base`` (the
    scene file's folder) that stays inside it; an absolute path, ``..`` or a link leading out of the
    folder is refused naming the key."""
    name = t.string("file", nonempty=True)
    shown = name if name.isprintable() else repr(name)
    shown = shown if len(shown) <= NAME_CHARS else shown[:NAME_CHARS - 3] + "..."
    why = textfile.outside_problem(base, name, shown, "the scene file's folder", "a trace file lies inside it",
                                   "a trace file is named relative to the scene file's folder")
    if why:
        t.fail("file", why)
    return str(pathlib.Path(base).resolve() / pathlib.PurePath(name)), shown


def _header(head: list[str]) -> str:
    """A header's columns as a message names them: word names only, at most :data:`NAME_CHARS`
    characters in all (a first line that is not a header is not quoted)."""
    n = f"{len(head)} column{'s' if len(head) != 1 else ''}"
    if not all(_WORD.fullmatch(h) for h in head):
        return f"{n}, not a header line (a name that is not a word of letters, digits and _)"
    names = ", ".join(head)
    return f"{n}: {names if len(names) <= NAME_CHARS else names[:NAME_CHARS - 3] + '...'}"


def _read_trace(text: str, fail) -> tuple[str, np.ndarray, np.ndarray]:
    """(x column's name, x, speed_rpm) of a trace's CSV text, every value in its column's range
    (:data:`COLUMNS`); ``fail(message)`` names the line and column, never quotes the text."""
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1)
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        fail("no header")
    head = [h.strip() for h in lines[0][1].split(",")]
    x_name = next((h for h in ("angle_deg", "time_s") if h in head), None)
    if x_name is None or "speed_rpm" not in head:
        fail(f"needs the columns angle_deg (or time_s) and speed_rpm; its header (line {lines[0][0]}) has "
             f"{_header(head)}")
    for c in (x_name, "speed_rpm"):
        if head.count(c) > 1:
            fail(f"the header (line {lines[0][0]}) has the column {c} twice")
    cols = [(head.index(c), c) for c in (x_name, "speed_rpm")]
    rows = []
    for n, ln in lines[1:]:
        cells = ln.split(",")
        if len(cells) != len(head):
            fail(f"line {n}: {len(cells)} value{'s' if len(cells) != 1 else ''} for the header's {len(head)} columns")
        row = []
        for i, c in cols:
            try:
                v = float(cells[i])
            except ValueError:
                fail(f"line {n}, column {i + 1} ({c}): not a number")
            msg = schema.problem(COLUMNS[c], v)
            if msg:
                fail(f"line {n}, column {i + 1} ({c}): {msg}")
            row.append(v)
        rows.append(row)
    data = np.array(rows, dtype=np.float64).reshape(-1, 2)
    x, y = data[:, 0], data[:, 1]
    if len(x) < 4:
        fail(f"{len(x)} sample{'s' if len(x) != 1 else ''}: a cycle needs at least 4")
    if np.any(np.diff(x) <= 0):
        j = int(np.flatnonzero(np.diff(x) <= 0)[0])
        fail(f"{x_name} must increase from sample to sample (line {lines[j + 1][0]} to {lines[j + 2][0]}: "
             f"{float(x[j])!r} then {float(x[j + 1])!r})")
    if np.any(y <= 0):
        fail(f"line {lines[int(np.flatnonzero(y <= 0)[0]) + 1][0]}: speed_rpm must be > 0 (in the belt's "
             "direction of travel)")
    return x_name, x, y


def _trace(t, pulley: str, base: str, harmonics: int, rpm: float, key: str) -> list[Fluctuation]:
    """The harmonics of a measured speed trace (see the module docstring), each in the range of a
    hand-written harmonic's fields (``fluctuation.order`` or ``frequency_hz``, ``amplitude_deg``,
    ``phase_deg``)."""
    path, shown = _trace_file(t, base)

    def fail(msg):
        t.fail("file", f"{shown}: {msg}")

    x_name, x, y = _read_trace(textfile.read_text(path, "csv", lambda _path, msg: fail(msg)), fail)
    if harmonics > (len(x) - 1) // 2:
        t.fail("harmonics", f"{harmonics} harmonics need at least {2 * harmonics + 1} samples, the trace has {len(x)}")
    cycle = x[-1] - x[0]
    k = np.arange(1, harmonics + 1)
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            grid = x[0] + cycle * np.arange(GRID) / GRID
            w = np.interp(grid, x, y)
            mean = float(np.mean(w))
            R = 2.0 * np.fft.rfft(w / mean - 1.0)[1:harmonics + 1] / GRID  # relative speed: sum |R_k| cos(k phi + arg R_k)
            if x_name == "angle_deg":
                per, rate = "rev", k * 360.0 / cycle
                amp = np.abs(R) / rate  # rad: the integral of the relative speed over the crank angle
            else:
                per, rate = "s", k / cycle
                amp = (mean * 2 * math.pi / 60.0) * np.abs(R) / (2 * math.pi * rate)
            amp, phase = np.degrees(amp), np.degrees(np.angle(R))  # the integral of cos(x + psi) is sin(x + psi)
    except FloatingPointError:
        fail("its harmonics overflow float64")
    if per == "s" and (abs(mean / abs(rpm) - 1.0) > SPEED_TOLERANCE if rpm else True):
        fail(f"the trace's mean speed {mean:.6g} rpm is not the pulley's speed_rpm {abs(rpm)!r} "
             f"(within {100 * SPEED_TOLERANCE:g} %): a trace against time carries its own speed")
    unit = "deg" if per == "rev" else "s"
    fields = (("order" if per == "rev" else "frequency_hz", rate), ("amplitude_deg", amp), ("phase_deg", phase))
    for f, values in fields:
        for j, v in enumerate(values):
            msg = schema.problem(schema.FIELDS[f"fluctuation.{f}"], float(v))
            if msg:
                fail(f"harmonic {j + 1} of its cycle of {cycle:.6g} {unit}: {f} {msg}")
    name = os.path.basename(path)
    return [Fluctuation(pulley=pulley, per=per, rate=_arr(r), amplitude_deg=_arr(a), phase_deg=_arr(p),
                        file=name, key=key) for r, a, p in zip(rate, amp, phase)]
