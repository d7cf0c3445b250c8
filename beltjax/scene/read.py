"""A whole scene: the sections read, the effects and the layout checked, from a dict, a file or a
string (errors: one line naming the key)."""

from __future__ import annotations

import functools
import os
from typing import Any

import jax.numpy as jnp

from beltjax import geometry, textfile
from beltjax.tomltable import describe
from beltjax.scene.spec import Scene, TENSIONER, drive_pulley_index
from beltjax.scene import fluctuations as fluctuation_tables
from beltjax.scene.sections import _TOP_KEYS, _check_effects, _check_listed_effects, _check_run_settings, _fail, _parse_belt, _parse_decouplers, _parse_initial, _parse_isolator, _parse_model, _parse_pulley, _parse_route, _parse_simulation, _parse_span_loads, _parse_tensioner, _parse_torques, _num, _table


def _key_for(route_idx, scene_names, order):
    """Key path of a route entry for geometry errors."""
    name = order[route_idx]
    if name == TENSIONER:
        return "tensioner"
    return f"pulley[{scene_names.index(name)}].center"


def _check_geometry(scene: Scene, source: str):
    order = scene.route.order
    names = [p.name for p in scene.pulleys]
    if scene.tensioner is not None and scene.tensioner.arm_angle_deg is None:
        # the arm angle is not known yet: check the fixed pulleys against each other
        fixed = [i for i, n in enumerate(order) if n != TENSIONER]
        for a in range(len(fixed)):
            for b in range(a + 1, len(fixed)):
                pa, pb = scene.pulley(order[fixed[a]]), scene.pulley(order[fixed[b]])
                D = float(jnp.linalg.norm(pa.center - pb.center))
                if D <= float(pa.radius + pb.radius):
                    _fail(
                        _key_for(fixed[b], names, order),
                        f"pulleys {pa.name!r} and {pb.name!r} overlap: centre distance {D:.6g} m "
                        f"<= R1 + R2 = {float(pa.radius + pb.radius):.6g} m",
                        source,
                    )
        return None
    try:
        g = scene.geometry()
    except geometry.GeometryError as e:
        if e.kind in ("overlap", "tangent", "radius"):
            involved = [i for i in e.pulleys if order[i] == TENSIONER]
            if involved:
                key = "tensioner.arm_angle_deg"
            else:
                key = _key_for(max(e.pulleys, key=lambda i: names.index(order[i])), names, order)
        else:
            key = "route.order"
        _fail(key, str(e), source)
    return g


def parse_scene(data: dict[str, Any], source: str = "<dict>") -> Scene:
    """Validate a scene given as a dict (the parsed TOML) and build a :class:`Scene`.

    source: a label kept on the scene and on errors (e.g. the file path).
    Raises :class:`SceneError` (one line, starting with the key path).
    """
    top = _table(data, "", source, _TOP_KEYS)
    description = top.string("description", required=False, default="")
    if "belt" not in data:
        _fail("belt", "missing (required table [belt])", source)
    belt = _parse_belt(data["belt"], source)
    if "pulley" not in data:
        _fail("pulley", "missing (give the pulleys as [[pulley]] tables)", source)
    raw = data["pulley"]
    if not isinstance(raw, list):
        _fail("pulley", f"expected an array of tables [[pulley]], got {describe(raw)}", source)
    if not raw:
        _fail("pulley", "at least one [[pulley]] is required", source)
    pulleys = tuple(_parse_pulley(p, i, source) for i, p in enumerate(raw))
    seen: dict[str, int] = {}
    for i, p in enumerate(pulleys):
        if p.name in seen:
            _fail(f"pulley[{i}].name", f"duplicated name {p.name!r} (also pulley[{seen[p.name]}])", source)
        seen[p.name] = i
    drive = drive_pulley_index(pulleys)
    for i, p in enumerate(raw):
        if i != drive and isinstance(p, dict) and "speed_rpm" in p:
            _fail(
                f"pulley[{i}].speed_rpm",
                f"only the drive pulley takes a speed: a driven pulley (driven = true), else the first "
                f"pulley (here pulley[{drive}], {pulleys[drive].name!r})",
                source,
            )
    tensioner = _parse_tensioner(data["tensioner"], source) if "tensioner" in data else None
    if "route" not in data:
        _fail("route", "missing (required table [route] with order = [...])", source)
    route = _parse_route(data["route"], [p.name for p in pulleys], tensioner is not None, source)
    model = _parse_model(data.get("model", {}), source)
    order = route.order
    spans = route.span_names
    free_names = [n for n in order if n == TENSIONER or not next(p for p in pulleys if p.name == n).driven]
    N = model.elements_per_span
    torques = _parse_torques(data["torque"], free_names, source) if "torque" in data else ()
    decouplers = _parse_decouplers(data["decoupler"], free_names, pulleys[drive].name, source) \
        if "decoupler" in data else ()
    isolator = _parse_isolator(data["isolator"], pulleys[drive], source) if "isolator" in data else None
    fluctuations = ()
    if "fluctuation" in data:
        if not isinstance(data["fluctuation"], list):
            _fail("fluctuation", f"expected an array of tables [[fluctuation]], got {describe(data['fluctuation'])}",
                  source)
        dp = pulleys[drive]
        base = os.path.dirname(os.path.abspath(source)) if os.path.isfile(source) else os.getcwd()
        fluctuations = fluctuation_tables.parse(data["fluctuation"], (dp.name, dp.driven, float(dp.speed_rpm)), base,
                                                _table, _num, source)
    span_loads = (
        _parse_span_loads(data["span_load"], spans, N, model.fidelity, source) if "span_load" in data else ()
    )
    initial = _parse_initial(data.get("initial", {}), free_names, tensioner is not None, source)
    simulation = _parse_simulation(data.get("simulation", {}), spans, N, model.fidelity, source)
    scene = Scene(
        belt=belt,
        pulleys=pulleys,
        tensioner=tensioner,
        route=route,
        model=model,
        source=source,
        description=description,
        torques=torques,
        span_loads=span_loads,
        fluctuations=fluctuations,
        decouplers=decouplers,
        isolator=isolator,
        initial=initial,
        simulation=simulation,
    )
    _check_effects(scene, source)
    g = _check_geometry(scene, source)
    if g is not None and tensioner is None and belt.length is not None:
        path = float(g.length)
        if float(belt.length) >= path:
            _fail(
                "belt.length",
                f"{float(belt.length)!r} m is not shorter than the belt path {path:.6g} m "
                "between fixed pulleys: the belt would be slack",
                source,
            )
    from beltjax import validate  # (imports this module)

    problem = validate.scene_problem(scene)
    if problem is not None:
        _fail(*problem, source)
    _check_listed_effects(scene, data, source)
    _check_run_settings(scene, source)
    return scene


def load_scene(path: str | os.PathLike) -> Scene:
    """Read and validate a TOML scene file; returns a :class:`Scene`.

    Raises :class:`SceneError` (one line) for a missing file, one that is not a regular file
    (a pipe, a device, a directory) or larger than the limit, text that is not UTF-8 (a
    byte-order mark is accepted), malformed TOML (with the line and column), values no key can
    carry (see :mod:`beltjax.textfile`) or an invalid scene.
    """
    p = textfile.file_name(path, "scene", _fail)
    data = textfile.load_toml(p, "scene", functools.partial(_fail, source=p))
    return parse_scene(data, source=p)


def loads_scene(text: str, source: str = "<string>") -> Scene:
    """Parse and validate a scene given as TOML text (see :func:`load_scene`)."""
    data = textfile.loads_toml(text, source, functools.partial(_fail, source=source))
    return parse_scene(data, source=source)
