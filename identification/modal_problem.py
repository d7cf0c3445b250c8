"""The modal dataset as a problem: measured modes (frequency, label), configurations (scene, name),
the parameters to fit, parsed and checked (one-line errors naming the key); frequencies in Hz."""

from __future__ import annotations

import math
import pathlib
import re
from dataclasses import dataclass

from beltjax import drive, parameters, statics
from beltjax.scene import Scene, SceneError, load_scene
from beltjax.tomltable import check_document, show
from identification.data import DataError, dataset_file, number


#: parameters fitted in log space (positive by nature)
_POSITIVE = re.compile(
    r"^(belt\.(EA|EI|rhoA|length|static_tension)|.*\.(radius|mass|inertia|arm_length|"
    r"spring_stiffness|arm_mass|arm_inertia|pulley_mass|pulley_inertia|pulley_radius))$"
)


_LABEL = re.compile(r"^\s*(\d+)\s*(?:st|nd|rd|th)\s+(transverse|longitudinal|rotational)\b", re.I)


#: most Levenberg-Marquardt steps per matching round a dataset may ask for (the compiled loss history's length)
MAX_ITERATIONS = 1000
_KEYS = {"parameters", "per_configuration", "frequency_std_hz", "max_iterations", "configuration"}


_CONF_KEYS = {"name", "scene", "modes"}


@dataclass
class Measured:
    """One measured mode: order and kind from its label, optional span, frequency (Hz)."""

    label: str
    order: int
    kind: str
    span: str | None
    frequency_hz: float
    key: str


@dataclass
class Configuration:
    """One measured configuration: its scene and its measured modes."""

    name: str
    scene: Scene
    modes: list[Measured]
    key: str


def _fail(key: str, message: str):
    raise DataError(f"{key}: {message}", key)


def _parse_mode(m, key: str) -> Measured | None:
    if not isinstance(m, dict):
        raise DataError("a mode is a table { label = \"1st transverse\", frequency_hz = 30.0 }", key)
    unknown = set(m) - {"label", "span", "frequency_hz"}
    if unknown:
        raise DataError("unknown key (use label, span, frequency_hz)", f"{key}.{sorted(unknown)[0]}")
    label = m.get("label")
    if not isinstance(label, str):
        raise DataError("missing or not a string (e.g. \"1st transverse\")", f"{key}.label")
    if label.strip().lower().startswith("rigid"):
        return None
    hit = _LABEL.match(label)
    if not hit:
        raise DataError(f"{show(label)} is not '<n>th transverse|longitudinal|rotational'", f"{key}.label")
    f = number(m, "frequency_hz", key, positive=True)
    span = m.get("span")
    if span is not None and not isinstance(span, str):
        raise DataError("must be a span name such as \"crank-alternator\"", f"{key}.span")
    return Measured(label.strip(), int(hit.group(1)), hit.group(2).lower(), span, f, key)


def _parse_configuration(c, i: int, base: pathlib.Path) -> Configuration:
    key = f"modal.configuration[{i}]"
    if not isinstance(c, dict):
        raise DataError("must be a table with scene and modes", key)
    unknown = set(c) - _CONF_KEYS
    if unknown:
        raise DataError(f"unknown key (use {', '.join(sorted(_CONF_KEYS))})", f"{key}.{sorted(unknown)[0]}")
    if not isinstance(c.get("scene"), str):
        raise DataError("missing: the scene file of this configuration", f"{key}.scene")
    path = dataset_file(base, c["scene"], f"{key}.scene")
    try:
        scene = load_scene(path)
    except SceneError as exc:
        msg = str(exc)
        if exc.key == str(path):  # about the file itself: it names the file, not a key
            msg = msg[len(exc.key):].lstrip(": ")
        raise DataError(f"{path.name}: {msg}", f"{key}.scene") from None
    modes = c.get("modes")
    if not isinstance(modes, list) or not modes:
        raise DataError("missing or empty: list the measured modes", f"{key}.modes")
    parsed = [_parse_mode(m, f"{key}.modes[{j}]") for j, m in enumerate(modes)]
    parsed = [m for m in parsed if m is not None]
    if not parsed:
        raise DataError("only rigid-body modes: nothing to fit", f"{key}.modes")
    spans = drive.span_names(scene)
    for m in parsed:
        if m.span is not None and m.span not in spans:
            raise DataError(f"no span {show(m.span)} in {path.name} (spans: {', '.join(spans)})", f"{m.key}.span")
    name = c.get("name", path.stem)
    if not isinstance(name, str) or not name:
        raise DataError(f"must be a non-empty string, got {show(name)}", f"{key}.name")
    return Configuration(name, scene, parsed, key)


def _strings(section, name, required):
    v = section.get(name, [] if not required else None)
    if v is None:
        raise DataError("missing: list the parameter paths to fit, e.g. [\"belt.EI\"]", f"modal.{name}")
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise DataError("must be a list of parameter paths (strings)", f"modal.{name}")
    if len(set(v)) != len(v):
        raise DataError("lists a parameter twice", f"modal.{name}")
    if "belt.length" in v and "belt.static_tension" in v:
        raise DataError("lists both belt.length and belt.static_tension: the belt is given by "
                                         "one of them, so setting one overwrites the other", f"modal.{name}")
    return v


@dataclass
class Problem:
    """Parsed modal fit: configurations, fitted paths, per-configuration paths, sigma (Hz)."""

    configurations: list[Configuration]
    paths: list[str]
    per_configuration: list[str]
    sigma_hz: float | None
    max_iterations: int


def parse(section: dict, base: pathlib.Path) -> Problem:
    """The ``[modal]`` section of a dataset (see the module docstring); :class:`DataError` if bad."""
    if not isinstance(section, dict):
        raise DataError("must be a table", "modal")
    check_document(section, _fail, key="modal")  # bounds of every value, also for a section given as a dict
    unknown = set(section) - _KEYS
    if unknown:
        raise DataError(f"unknown key (use {', '.join(sorted(_KEYS))})", f"modal.{sorted(unknown)[0]}")
    paths = _strings(section, "parameters", True)
    if not paths:
        raise DataError("empty: name at least one parameter to fit", "modal.parameters")
    per = _strings(section, "per_configuration", False)
    for p in per:
        if p not in paths:
            raise DataError(f"{show(p)} is not among modal.parameters", "modal.per_configuration")
    confs = section.get("configuration")
    if not isinstance(confs, list) or not confs:
        raise DataError("missing: add [[modal.configuration]] tables", "modal.configuration")
    configurations = [_parse_configuration(c, i, base) for i, c in enumerate(confs)]
    named: dict[str, str] = {}
    for raw, c in zip(confs, configurations):  # a name keys the per-configuration values: no two alike
        if c.name in named:
            given = "name" if "name" in raw else "scene"
            raise DataError(f"configuration name {show(c.name)} is also that of "
                                                f"{named[c.name]} (a name defaults to the scene file's stem): "
                                                "give each configuration its own name", f"{c.key}.{given}")
        named[c.name] = c.key
    for c in configurations:
        for p in paths:
            try:
                parameters.check(c.scene, p)
            except parameters.ParameterError as exc:
                raise DataError(f"{exc} (in {c.key})", "modal.parameters") from None
    sigma = section.get("frequency_std_hz")
    sigma = None if sigma is None else number(section, "frequency_std_hz", "modal", positive=True)
    it = section.get("max_iterations", 50)
    if isinstance(it, bool) or not isinstance(it, int) or not 1 <= it <= MAX_ITERATIONS:
        raise DataError(f"must be a whole number from 1 to {MAX_ITERATIONS}, got {show(it)}", "modal.max_iterations")
    return Problem(configurations, paths, per, sigma, it)


def _start_value(scene: Scene, path: str) -> float:
    """The scene's value of ``path``; for the belt parameter the scene does not give (length or
    static_tension), the value its installation solves for."""
    v = float(parameters.get_value(scene, path))
    if math.isnan(v) and path in ("belt.length", "belt.static_tension"):
        inst = statics.install(drive.canonical(scene))
        v = float(inst.belt_length if path == "belt.length" else inst.tension)
    return v
