"""One schema for every scalar scene parameter: unit, accepted range and why.

Every number a scene file, a parameter path (:mod:`beltjax.parameters`), a sweep case or a
Python API argument can give is checked here, against one :class:`Field`: its unit, the
interval it must lie in (wide enough for every real belt drive, from an elastic cord to a
wide steel band, yet inside what float64 carries through the element energies, the statics
and the eigen-solves) and a one-phrase reason for the bounds.  :func:`problem` gives the
one-line message, e.g. ``must lie in [0, 1e+05] N m^2 (...), got 1e+20``; the caller puts
the key in front.  :func:`bad` is the same test vectorised over numpy arrays (sweeps).

Single-parameter ranges cannot catch everything float64 cannot carry; the derived limits
below are checked on the whole drive by :mod:`beltjax.validate`:

* :data:`MAX_SPAN_SPREAD`: the stiffest element of the shortest span against that of the
  longest, (EA / Le^2 + EI / Le^4) with Le = span / elements;
* :data:`MAX_STRING_SPREAD`: the longest span's stiffest element against its slowest string
  mode, (EA / Le^2 + EI / Le^4) / ((T + EI pi^2 / L^2) pi^2 / L^2) (needs the tension);
* :data:`MAX_BENDING_RATIO`: EI / (EA Le^2) of the shortest element (bending against axial);
* :data:`MAX_OFFSET_RATIO`: distance of the farthest centre from the origin against the
  drive's smallest length (shortest span or smallest radius);
* the drive pulley's belt speed (speed_rpm and target_speed_rpm on its radius): at most
  ``drive.speed``'s 1e4 m/s.

Measured on the bench belt (scripts in the commit messages): a 0.1 mm span beside 0.67 m
ones (spread 5e10) moved the long spans' frequencies by 18 % (1 mm, 5e6: 2e-9); EA / T =
1e10 with 16 elements (string spread 2.6e11) moved them by 1.7e-4 (1e9: 1.6e-5);
EI = 1e10 N m^2 (bending ratio 7e6) moved the rotational mode by 3e-4, EI = 1e20 by 400x;
the drive 1e8 m from the origin (ratio 2.7e9) moved frequencies by 8e-6 (1e6 m: 8e-8).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

#: the stiffest element of the shortest span against that of the longest (see the module doc)
MAX_SPAN_SPREAD = 1e8
#: the stiffest element against the slowest string mode of the longest span
MAX_STRING_SPREAD = 1e11
#: EI / (EA Le^2) of the shortest element
MAX_BENDING_RATIO = 1e6
#: farthest centre from the origin over the drive's smallest length
MAX_OFFSET_RATIO = 1e8


@dataclass(frozen=True)
class Field:
    """A scalar parameter: ``unit``; accepted range [low, high] (inclusive) with its reason
    ``why``; ``sign`` ">0" or ">=0" when a value of the wrong sign reads "must be > 0" (the
    physical rule) before the range; ``effect``: the model effect that owns it, if any (its
    module in :mod:`beltjax.drive.effects` reads its parameters from here; a scene that gives
    it, or a sweep or optimisation that moves it, without listing the effect is refused)."""

    unit: str
    low: float
    high: float
    why: str
    sign: str = ""
    effect: str = ""

    def range_text(self) -> str:
        """``[low, high] unit``."""
        unit = f" {self.unit}" if self.unit else ""
        return f"[{_g(self.low)}, {_g(self.high)}]{unit}"


def _g(x: float) -> str:
    return f"{x:g}"


_LEN = "m"
_CENTRE = Field(_LEN, -1e5, 1e5, "keep the drive near the origin: float64 round-off of the tangent geometry "
                                  "grows with the distance")
_RADIUS = Field(_LEN, 1e-4, 1e2, "from a 0.1 mm pin to a 100 m drum", ">0")
_MASS = Field("kg", 0.0, 1e6, "heavier than any pulley or flywheel (1000 t)", ">=0")
_INERTIA = Field("kg m^2", 1e-12, 1e6, "from a 1 mm steel pin to a 1000 t flywheel; outside, the mass matrix "
                                       "loses the belt", ">0")
_DAMPING = Field("N m s/rad", 0.0, 1e6, "a bearing or pivot this viscous is locked", ">=0")
_RPM = Field("rpm", -1e6, 1e6, "faster than any belt-driven shaft")
_ANGLE = Field("deg", -3600.0, 3600.0, "ten turns either way; beyond, sin and cos lose digits")
_TIME = Field("s", 0.0, 1e6, "11 days of simulated time", ">=0")
_FREQ = Field("Hz", 0.0, 1e6, "far above any belt-drive excitation", ">=0")
_MOMENT = Field("N m", -1e8, 1e8, "beyond any shaft's torque")
_FRICTION = Field("", 1e-3, 5.0, "from a lubricated contact to beyond any rubber on metal (0.3-1.5)", ">0")

#: every scalar: "belt.<key>", "pulley.<key>", "tensioner.<key>", "torque.<key>",
#: "span_load.<key>", "simulation.<key>", "initial.<key>", and the API's "span.<key>"
FIELDS: dict[str, Field] = {
    "belt.EA": Field("N", 1.0, 1e10, "no belt is softer than an elastic cord (10 N) or stiffer than a 2 m wide, "
                                     "5 mm steel band (2e9 N)", ">0"),
    "belt.EI": Field("N m^2", 0.0, 1e5, "0 is a string; a 2 m wide, 10 mm steel band has 3.5e4; beyond, bending "
                                          "swamps the axial stiffness in the element matrices", ">=0"),
    "belt.rhoA": Field("kg/m", 1e-6, 1e3, "from a 10 um tape to a heavy conveyor belt (100 kg/m); beyond, the "
                                          "modes leave any meaningful frequency", ">0"),
    "belt.CA": Field("N s", 0.0, 1e6, "the thesis' belt has 3-47 N s", ">=0", "belt_damping"),
    "belt.static_tension": Field("N", 1e-6, 1e8, "from a hanging thread to a conveyor's 1e7 N", ">0"),
    "belt.length": Field(_LEN, 1e-3, 1e6, "from a 1 mm loop to a 1000 km belt", ">0"),
    "belt.friction_coefficient": _FRICTION,
    "belt.groove_angle_deg": Field("deg", 10.0, 120.0, "V and ribbed belts have 30-40 deg grooves", ">0"),
    "belt.slip_speed": Field("m/s", 1e-3, 1e4, "the regularisation: above the sliding speeds that matter (at "
                                               "this speed an arc carries its installed capacity beyond its "
                                               "capacity)", ">0",
                             "belt_slip"),
    "pulley.center": _CENTRE,
    "pulley.radius": _RADIUS,
    "pulley.mass": _MASS,
    "pulley.inertia": _INERTIA,
    "pulley.speed_rpm": _RPM,
    "pulley.acceleration_rpm_per_s": Field("rpm/s", -1e7, 1e7, "0 to 1e6 rpm in 0.1 s"),
    "pulley.fluctuation_amplitude_deg": Field("deg", 0.0, 360.0, "a full turn", ">=0", "speed_fluctuation"),
    "pulley.fluctuation_frequency_hz": Field("Hz", 0.0, 1e6, "far above any belt-drive excitation", ">=0",
                                             "speed_fluctuation"),
    "pulley.cm_offset": Field(_LEN, -1e2, 1e2, "inside the pulley: the offset is shorter than the radius", "", "unbalance"),
    "pulley.bearing_damping": Field("N m s/rad", 0.0, 1e6, "a bearing this viscous is locked", ">=0",
                                    "bearing_damping"),
    "pulley.target_speed_rpm": _RPM,
    "pulley.friction_coefficient": _FRICTION,
    "tensioner.pivot": _CENTRE,
    "tensioner.arm_length": Field(_LEN, 1e-4, 1e2, "from 0.1 mm to 100 m", ">0"),
    "tensioner.pulley_radius": _RADIUS,
    "tensioner.arm_mass": _MASS,
    "tensioner.arm_inertia": Field("kg m^2", 0.0, 1e6, "beyond any tensioner arm", ">=0"),
    "tensioner.pulley_mass": _MASS,
    "tensioner.pulley_inertia": _INERTIA,
    "tensioner.spring_stiffness": Field("N m/rad", 1e-6, 1e8, "the thesis' spring has 21 N m/rad", ">0"),
    "tensioner.spring_preload_deg": _ANGLE,
    "tensioner.arm_angle_deg": _ANGLE,
    "tensioner.arm_cm_distance": Field(_LEN, 0.0, 1e2, "along the arm: at most arm_length", ">=0"),
    "tensioner.damping": Field("N m s/rad", 0.0, 1e6, "a pivot this viscous is locked", ">=0", "tensioner_damping"),
    "tensioner.friction_moment": Field("N m", 0.0, 1e4, "beyond any tensioner's damping", ">=0", "tensioner_friction"),
    "tensioner.friction_asymmetry": Field("-", 0.01, 100.0, "asymmetric tensioners have 1.5-4", ">0",
                                          "tensioner_friction"),
    "tensioner.friction_speed": Field("rad/s", 1e-6, 10.0, "the regularisation: far below the arm's speeds", ">0",
                                      "tensioner_friction"),
    "tensioner.friction_stick_time": Field("s", 1e-7, 0.1, "the regularisation: far below the forcing's periods",
                                           ">0", "tensioner_friction"),
    "tensioner.stop_min_deg": _ANGLE,
    "tensioner.stop_max_deg": _ANGLE,
    "tensioner.stop_stiffness": Field("N m/rad", 1e-6, 1e9, "a contact stiffer than the spring", ">0"),
    "fluctuation.order": Field("-", 0.0, 1e3, "cycles per revolution: engines excite orders up to about 20", ">0",
                               "speed_fluctuation"),
    "fluctuation.frequency_hz": Field("Hz", 0.0, 1e6, "far above any belt-drive excitation", ">0", "speed_fluctuation"),
    "fluctuation.amplitude_deg": Field("deg", 0.0, 360.0, "a full turn", ">=0", "speed_fluctuation"),
    "fluctuation.phase_deg": Field("deg", -3600.0, 3600.0, "ten turns either way", "", "speed_fluctuation"),
    "decoupler.rotor_inertia": Field("kg m^2", 1e-9, 1e6, "an alternator rotor has about 3e-3", ">0"),
    "decoupler.stiffness": Field("N m/rad", 1e-6, 1e9, "decoupler springs have 1-100 N m/rad", ">0"),
    "decoupler.damping": Field("N m s/rad", 0.0, 1e6, "a decoupler this viscous is locked", ">=0"),
    "isolator.stiffness": Field("N m/rad", 1e-6, 1e9, "crank isolators have about 100-1000 N m/rad", ">0"),
    "isolator.damping": Field("N m s/rad", 0.0, 1e6, "an isolator this viscous is locked", ">=0"),
    "torque.mean_Nm": _MOMENT,
    "torque.amplitude_Nm": _MOMENT,
    "torque.frequency_hz": _FREQ,
    "torque.phase_deg": _ANGLE,
    "torque.t_start_s": _TIME,
    "torque.t_end_s": _TIME,
    "span_load.amplitude_N": Field("N", -1e8, 1e8, "beyond any belt's strength"),
    "span_load.frequency_hz": _FREQ,
    "span_load.phase_deg": _ANGLE,
    "span_load.t_start_s": _TIME,
    "span_load.t_end_s": _TIME,
    "simulation.dt_s": Field("s", 1e-9, 10.0, "from 1 ns to 10 s", ">0"),
    "simulation.rho_inf": Field("", 0.0, 1.0, "generalized-alpha's spectral radius at infinite frequency"),
    "simulation.rtol": Field("", 1e-14, 1e-2, "float64 resolves no finer; looser, the step's error control "
                                              "no longer follows the response (at rtol = 1 a damped drive "
                                              "gained energy)", ">0"),
    "simulation.atol": Field("", 1e-20, 1e-2, "in SI units of the state (m, rad, m/s, rad/s); looser, the "
                                              "error control lets the response go", ">0"),
    "simulation.output_dt_s": Field("s", 1e-9, 1e4, "from 1 ns to 3 hours", ">0"),
    "initial.rotation_deg": _ANGLE,
    "initial.arm_angle_deg": _ANGLE,
    # Python API arguments (beltjax.span.analyse_span, analyse_statics/modes, analyse_campbell)
    "span.length": Field(_LEN, 1e-4, 1e4, "shorter, the element stiffness EI / Le^4 leaves what float64 "
                                         "eigen-solves resolve", ">0"),
    "span.tension": Field("N", 0.0, 1e8, "0 (a beam) to a conveyor's 1e7 N", ">=0"),
    "span.speed": Field("m/s", -1e4, 1e4, "twice the speed of sound in steel"),
    "drive.speed": Field("m/s", 0.0, 1e4, "twice the speed of sound in steel; the belt runs in the route's "
                                          "direction", ">=0"),
    "drive.rpm": Field("rpm", 0.0, 1e6, "speeds of the drive pulley, >= 0; faster than any belt-driven shaft",
                       ">=0"),
}

#: the value a scene file's missing key takes: the one statement of every default (the scene
#: reader fills a missing key from here, the writer leaves a key at its default out, the spec's
#: pytrees take theirs from here, and the README's ranges table shows them).  A key not listed is
#: required, or absent (None) when missing.
DEFAULTS: dict[str, object] = {
    "belt.CA": 0.0,
    "belt.slip_speed": 100.0,
    "pulley.speed_rpm": 0.0,
    "pulley.acceleration_rpm_per_s": 0.0,
    "pulley.fluctuation_amplitude_deg": 0.0,
    "pulley.fluctuation_frequency_hz": 0.0,
    "pulley.cm_offset": (0.0, 0.0),
    "pulley.bearing_damping": 0.0,
    "tensioner.arm_cm_distance": 0.0,
    "tensioner.damping": 0.0,
    "tensioner.friction_moment": 0.0,
    "tensioner.friction_asymmetry": 1.0,
    "tensioner.friction_speed": 0.01,
    "tensioner.friction_stick_time": 3e-4,
    "tensioner.stop_stiffness": 1e4,
    "fluctuation.phase_deg": 0.0,
    "decoupler.damping": 0.0,
    "isolator.damping": 0.0,
    "torque.mean_Nm": 0.0,
    "torque.amplitude_Nm": 0.0,
    "torque.frequency_hz": 0.0,
    "torque.phase_deg": 0.0,
    "torque.t_start_s": 0.0,
    "span_load.phase_deg": 0.0,
    "span_load.t_start_s": 0.0,
    "route.back_side": (),
    "route.direction": "cw",
    "model.fidelity": "ancf",
    "model.elements_per_span": 16,
    "model.effects": (),
    "model.bending": "linear",
    "simulation.rho_inf": 0.9,
    "simulation.rtol": 1e-6,
    "simulation.atol": 1e-9,
    "simulation.max_steps": 1_000_000,
}


def default(key: str):
    """The default of the scene-file key ``key`` (``"tensioner.friction_speed"``; see
    :data:`DEFAULTS`), or None when a missing key is required or absent."""
    return DEFAULTS.get(key)


_INDEXED = re.compile(r"^(pulley|torque|span_load|fluctuation|decoupler)\[\d+\]\.(.+)$")


def field(key: str) -> Field | None:
    """The :class:`Field` of a scene-file key (``pulley[1].radius``, ``torque[0].mean_Nm``), a
    parameter path (``pulley.alternator.center.x``, ``tensioner.pivot.y``, ``belt.EI``) or a
    schema name (``pulley.radius``); None if the key names no scalar."""
    m = _INDEXED.match(key)
    if m:
        key = f"{m.group(1)}.{m.group(2)}"
    parts = key.split(".")
    if parts[-1] in ("x", "y") and len(parts) >= 3:
        parts = parts[:-1]
    if parts[0] in ("pulley", "decoupler") and len(parts) == 3:
        parts = [parts[0], parts[2]]
    return FIELDS.get(".".join(parts))


def problem(f: Field, value) -> str | None:
    """Why ``value`` is not accepted for ``f`` (one phrase for after the key), or None."""
    try:
        v = float(value)
        shown = repr(value) if type(value) in (int, float) else repr(v)
    except OverflowError:  # an integer beyond float64
        v, shown = (math.inf if value > 0 else -math.inf), f"an integer of about {int(value.bit_length() * math.log10(2)) + 1} digits"
    if math.isnan(v) or (math.isinf(v) and not shown.startswith("an integer")):
        return f"must be finite, got {shown}"
    if f.sign == ">0" and not v > 0:
        return f"must be > 0, got {shown}"
    if f.sign == ">=0" and not v >= 0:
        return f"must be >= 0, got {shown}"
    if not f.low <= v <= f.high:
        return f"must lie in {f.range_text()} ({f.why}), got {shown}"
    return None


def number(value, key: str, field: str) -> float:
    """A concrete API argument as a float in the range of the schema ``field``, else a
    :class:`beltjax.errors.BeltjaxError` naming ``key`` (e.g. ``speed: must be finite, got nan``)."""
    from beltjax.errors import BeltjaxError

    try:
        if isinstance(value, (bool, str, bytes)) or np.ndim(value) != 0:
            raise TypeError
        v = float(value)
    except (TypeError, ValueError):
        raise BeltjaxError(f"expected a number, got {value!r}", key) from None
    msg = problem(FIELDS[field], v)
    if msg:
        raise BeltjaxError(msg, key)
    return v


def bad(f: Field, values) -> np.ndarray:
    """Vectorised :func:`problem`: a bool array, True where a value is not accepted."""
    v = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore"):
        return ~(np.isfinite(v) & (v >= f.low) & (v <= f.high) & ((v > 0) if f.sign == ">0" else True))


def read_number(t, k: str, group: str, *, required=True):
    """The number at key ``k`` of a :class:`beltjax.tomltable.Table` ``t`` (the table's own type
    checks), in the range of the field ``group.k`` (else ``t.fail``, naming the key); a missing
    optional key takes its :data:`DEFAULTS` value (None if it has none)."""
    v = t.number(k, required=required, default=DEFAULTS.get(f"{group}.{k}"))
    if t.has(k):
        msg = problem(FIELDS[f"{group}.{k}"], t.raw(k, True))
        if msg:
            t.fail(k, msg)
    return v


def read_vector(t, k: str, group: str, *, required=True):
    """The [x, y] at key ``k`` of table ``t``, each component in the range of ``group.k``; a
    missing optional key takes its :data:`DEFAULTS` value (None if it has none)."""
    d = DEFAULTS.get(f"{group}.{k}")
    v = t.vector2(k, required=required, default=None if d is None else list(d))
    if t.has(k):
        for x in t.raw(k, True):
            msg = problem(FIELDS[f"{group}.{k}"], x)
            if msg:
                t.fail(k, msg)
    return v


# --------------------------------------------------------------------------- derived limits


def element_stiffness(EA, EI, Le, flexible: bool = True):
    """Stiffness scale of an element of length ``Le`` (m): EA / Le^2 + EI / Le^4 (ANCF
    spans, per metre of belt), or EA / Le (the rotational model's bars).  numpy, vectorised."""
    return EA / Le**2 + EI / Le**4 if flexible else EA / Le


def string_spread(EA, EI, T, L, n_elements):
    """The stiffest element of a span (L m, n_elements, tension T N) over its slowest
    transverse mode, (EA / Le^2 + EI / Le^4) / ((T + EI pi^2 / L^2) pi^2 / L^2): float64
    eigen-solves resolve up to :data:`MAX_STRING_SPREAD`.  numpy, vectorised."""
    with np.errstate(all="ignore"):
        return element_stiffness(EA, EI, L / n_elements) / ((T + EI * np.pi**2 / L**2) * np.pi**2 / L**2)


# --------------------------------------------------------------------------- documentation

_SCENE_GROUPS = ("belt", "pulley", "tensioner", "fluctuation", "decoupler", "isolator", "torque", "span_load", "simulation",
                 "initial")


def rows(groups=_SCENE_GROUPS) -> list[tuple[str, str, str, str, str]]:
    """(key, unit, accepted range, default, why) of every scene-file field, for the documentation
    (default "-": the key is required, or absent when missing)."""
    out = []
    for key, f in FIELDS.items():
        if key.split(".")[0] in groups:
            rng = f"({_g(f.low)}, {_g(f.high)}]" if f.sign == ">0" and f.low == 0 else f"[{_g(f.low)}, {_g(f.high)}]"
            out.append((key, f.unit or "-", rng, _default_text(DEFAULTS.get(key)), f.why))
    return out


def _default_text(d) -> str:
    if d is None:
        return "-"
    if isinstance(d, tuple):
        return "[" + ", ".join(_g(x) for x in d) + "]"
    return _g(d)


def derived_rows() -> list[tuple[str, str, str]]:
    """(quantity, limit, why) of the derived limits."""
    return [
        ("(EA/Le^2 + EI/Le^4) of the shortest span over that of the longest (Le = span / elements)",
         f"<= {_g(MAX_SPAN_SPREAD)}", "float64 eigen-solves lose the long spans' frequencies beside a pinched span"),
        ("(EA/Le^2 + EI/Le^4) over (T + EI pi^2/L^2) pi^2/L^2 of the longest span (T: the given tension, or the installed one of a belt given by length)",
         f"<= {_g(MAX_STRING_SPREAD)}", "the axial stiffness swamps the string stiffness: frequencies off by 1e-4"),
        ("EI / (EA Le^2) of the shortest element", f"<= {_g(MAX_BENDING_RATIO)}",
         "bending swamps the axial stiffness: the rotational and longitudinal modes are lost"),
        ("farthest centre from the origin over the smallest span or radius", f"<= {_g(MAX_OFFSET_RATIO)}",
         "round-off of the tangent geometry swamps the belt's stretch"),
        ("belt speed of the drive pulley, abs(speed_rpm) 2 pi / 60 R (and its target_speed_rpm)",
         f"<= {_g(FIELDS['drive.speed'].high)} m/s", FIELDS["drive.speed"].why.split(";")[0]),
        ("length of a pulley's centre-of-mass offset cm_offset", "< radius", "inside the pulley"),
        ("tensioner.arm_cm_distance", "<= arm_length", "along the arm"),
    ]


def scene_doc() -> str:
    """The accepted ranges as text for the scene-file documentation (``beltjax.scene``)."""
    rs = rows()
    w = [max(len(r[i]) for r in rs) for i in range(4)]
    lines = ["Accepted ranges (beltjax.schema; a value outside is an error naming the key, the",
             "value, the range and its reason), with the default a missing key takes (\"-\": none):", ""]
    lines += [f"    {k:<{w[0]}}  {u:<{w[1]}}  {r:<{w[2]}}  {d:<{w[3]}}  {why}" for k, u, r, d, why in rs]
    lines += ["", "Derived limits on the whole drive (float64 cannot carry more):", ""]
    lines += [f"    {q}: {lim} ({why})" for q, lim, why in derived_rows()]
    return "\n".join(lines) + "\n"


def markdown_table() -> str:
    """The accepted ranges as a Markdown table (for the README)."""
    lines = ["| parameter | unit | accepted range | default | why |", "|---|---|---|---|---|"]
    lines += [f"| `{k}` | {u} | {r} | {d} | {why} |" for k, u, r, d, why in rows()]
    lines += ["", "| derived limit | bound | why |", "|---|---|---|"]
    lines += [f"| {q} | {lim} | {why} |" for q, lim, why in derived_rows()]
    return "\n".join(lines) + "\n"
