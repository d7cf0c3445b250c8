"""Writing a scene as a TOML scene file that reads back to the same scene (every number to the
last bit): the optimiser's and a script's way to save a changed drive.

Keys are written where the reader needs them and where a value differs from what the reader
takes for a missing key (:data:`beltjax.schema.DEFAULTS`), so the file stays as short as a
hand-written one.  A measured crank-speed trace is written as the harmonics it was read into.
:func:`dumps_scene` reads its own text back and raises :class:`SceneError` naming the first key
that does not come back (a scene built in code with values no scene file may hold, say), so a
written file is the scene or nothing.
"""

from __future__ import annotations

import dataclasses
import os

import jax
import numpy as np

from beltjax import schema, tomlwrite
from beltjax.scene.spec import Scene, SceneError, drive_pulley_index, require_scene


def _f(x) -> float:
    return float(np.asarray(x))


def _put(table: dict, key: str, x, group: str | None = None) -> None:
    """``table[key]`` = x (a float, or a list for a vector) unless x is None or the default of
    the scene-file key ``group.key`` (:data:`beltjax.schema.DEFAULTS`; no group: always written)."""
    if x is None:
        return
    a = np.asarray(x, dtype=float)
    d = None if group is None else schema.default(f"{group}.{key}")
    if d is not None and np.array_equal(a, np.broadcast_to(np.asarray(d, dtype=float), a.shape)):
        return
    table[key] = [float(v) for v in a] if a.ndim else float(a)


def _belt(b) -> dict:
    t = {"EA": _f(b.EA), "EI": _f(b.EI), "rhoA": _f(b.rhoA)}
    _put(t, "static_tension", b.static_tension)
    _put(t, "length", b.length)
    _put(t, "CA", b.CA, "belt")
    _put(t, "friction_coefficient", b.friction_coefficient)
    _put(t, "groove_angle_deg", b.groove_angle_deg)
    _put(t, "slip_speed", b.slip_speed, "belt")
    return t


def _pulley(p, is_drive: bool) -> dict:
    t = {"name": p.name, "center": [float(v) for v in np.asarray(p.center)], "radius": _f(p.radius),
         "mass": _f(p.mass), "inertia": _f(p.inertia)}
    if p.driven:
        t["driven"] = True
    if is_drive:
        t["speed_rpm"] = _f(p.speed_rpm)
    else:
        _put(t, "speed_rpm", p.speed_rpm, "pulley")  # (no scene file may give it: the read-back says so)
    for k in ("acceleration_rpm_per_s", "fluctuation_amplitude_deg", "fluctuation_frequency_hz", "cm_offset",
              "bearing_damping"):
        _put(t, k, getattr(p, k), "pulley")
    _put(t, "target_speed_rpm", p.target_speed_rpm)
    _put(t, "friction_coefficient", p.friction_coefficient)
    return t


def _tensioner(x) -> dict:
    t = {"pivot": [float(v) for v in np.asarray(x.pivot)]}
    for k in ("arm_length", "pulley_radius", "arm_mass", "arm_inertia", "pulley_mass", "pulley_inertia",
              "spring_stiffness", "spring_preload_deg"):
        t[k] = _f(getattr(x, k))
    _put(t, "arm_angle_deg", x.arm_angle_deg)
    for k in ("arm_cm_distance", "damping", "friction_moment", "friction_asymmetry", "friction_speed",
              "friction_stick_time", "stop_min_deg", "stop_max_deg", "stop_stiffness"):
        _put(t, k, getattr(x, k), "tensioner")
    return t


def _loads(items, group: str, first: str, required: tuple[str, ...], optional: tuple[str, ...]) -> list[dict]:
    out = []
    for x in items:
        t = {first: getattr(x, first)}
        for k in required:
            t[k] = _f(getattr(x, k))
        for k in optional:
            _put(t, k, getattr(x, k), group)
        _put(t, "t_end_s", getattr(x, "t_end_s", None))
        out.append(t)
    return out


def _fluctuation(f) -> dict:
    t = {"pulley": f.pulley, ("order" if f.per == "rev" else "frequency_hz"): _f(f.rate)}
    if f.rpm is not None:
        t["rpm"] = [float(v) for v in np.asarray(f.rpm)]
        t["amplitude_deg"] = [float(v) for v in np.asarray(f.amplitude_deg)]
    else:
        t["amplitude_deg"] = _f(f.amplitude_deg)
    _put(t, "phase_deg", f.phase_deg, "fluctuation")
    return t


def _simulation(s) -> dict:
    t = {}
    defaults = {f.name: f.default for f in dataclasses.fields(s)}
    for k, v in ((f.name, getattr(s, f.name)) for f in dataclasses.fields(s)):
        if v is not None and v != defaults[k]:
            t[k] = list(v) if isinstance(v, tuple) else v
    return t


def scene_document(scene: Scene) -> dict:
    """The scene as the dict a scene file parses to (SI units, the file's keys)."""
    doc: dict = {}
    if scene.description:
        doc["description"] = scene.description
    doc["belt"] = _belt(scene.belt)
    drive = drive_pulley_index(scene.pulleys)
    doc["pulley"] = [_pulley(p, i == drive) for i, p in enumerate(scene.pulleys)]
    if scene.tensioner is not None:
        doc["tensioner"] = _tensioner(scene.tensioner)
    r = scene.route
    doc["route"] = {"order": list(r.order), "back_side": list(r.back_side), "direction": r.direction}
    m = scene.model
    doc["model"] = {"fidelity": m.fidelity, "elements_per_span": m.elements_per_span, "effects": list(m.effects)}
    if m.bending != schema.default("model.bending"):
        doc["model"]["bending"] = m.bending
    if scene.torques:
        doc["torque"] = _loads(scene.torques, "torque", "pulley", (), ("mean_Nm", "amplitude_Nm", "frequency_hz", "phase_deg",
                                                              "t_start_s"))
    if scene.fluctuations:
        doc["fluctuation"] = [_fluctuation(f) for f in scene.fluctuations]
    if scene.decouplers:
        doc["decoupler"] = _loads(scene.decouplers, "decoupler", "pulley", ("rotor_inertia", "stiffness"), ("damping",))
    if scene.isolator is not None:
        doc["isolator"] = _loads([scene.isolator], "isolator", "pulley", ("stiffness",), ("damping",))[0]
    if scene.span_loads:
        doc["span_load"] = [{"span": x.span, "node": x.node, **t} for x, t in zip(
            scene.span_loads, _loads(scene.span_loads, "span_load", "span", ("amplitude_N", "frequency_hz"),
                                     ("phase_deg", "t_start_s")))]
    initial = {}
    if scene.initial.rotation_deg:
        initial["rotation_deg"] = {name: float(v) for name, v in scene.initial.rotation_deg}
    if scene.initial.arm_angle_deg is not None:
        initial["arm_angle_deg"] = float(scene.initial.arm_angle_deg)
    if initial:
        doc["initial"] = initial
    simulation = _simulation(scene.simulation)
    if simulation:
        doc["simulation"] = simulation
    _keep_listed(doc, scene)
    return doc


def _keep_listed(doc: dict, scene: Scene) -> None:
    """Each listed effect's key (:data:`beltjax.scene.sections.LISTED_KEYS`) written even at its
    default 0, which the reader would otherwise refuse as an effect that changes nothing."""
    from beltjax.scene.sections import listed_without_key

    for name, table, key in listed_without_key(scene, doc):
        if table == "pulley":
            i = drive_pulley_index(scene.pulleys) if name == "speed_fluctuation" else 0
            _put(doc["pulley"][i], key, getattr(scene.pulleys[i], key))
        elif table in doc:
            _put(doc[table], key, getattr(scene.belt if table == "belt" else scene.tensioner, key))


def _comparable(scene: Scene) -> Scene:
    """The scene without what a file does not carry back: its label, and which trace a
    crank-speed harmonic was read from (its numbers stay)."""
    flucts = tuple(dataclasses.replace(f, file="", key="") for f in scene.fluctuations)
    return dataclasses.replace(scene, source="", fluctuations=flucts)


def first_difference(a: Scene, b: Scene) -> str | None:
    """The key path of the first number or structure in which ``a`` and ``b`` differ (bit for bit;
    NaN equals NaN; the scenes' labels and trace file names not compared), or None."""
    la, ta = jax.tree_util.tree_flatten_with_path(_comparable(a))
    lb, tb = jax.tree_util.tree_flatten_with_path(_comparable(b))
    if ta != tb:
        return "the scene's structure"
    for (path, x), (_, y) in zip(la, lb):
        x, y = np.asarray(x), np.asarray(y)
        if x.shape != y.shape or not np.array_equal(x, y, equal_nan=True):
            return jax.tree_util.keystr(path).lstrip(".")
    return None


def dumps_scene(scene: Scene, header: str = "") -> str:
    """The scene as TOML text that reads back to ``scene`` bit for bit (``header``: comment
    lines written on top).  Raises :class:`SceneError` when it does not (one line naming the
    key, e.g. a value that no scene file may hold)."""
    from beltjax.scene.read import loads_scene

    require_scene(scene)
    notes = [header] if header else []
    files = sorted({f.file for f in scene.fluctuations if f.file})
    comments = {"": "\n".join(notes)}
    if files:
        comments["fluctuation"] = f"the harmonics read from {', '.join(files)}"
    text = tomlwrite.dumps(scene_document(scene), comments)
    try:
        back = loads_scene(text, source=scene.source)
    except SceneError as exc:
        raise SceneError(f"the written scene does not read back: {exc}", exc.key) from None
    where = first_difference(scene, back)
    if where is not None:
        raise SceneError(f"the written scene reads back with another {where}", where)
    return text


def write_scene(scene: Scene, path: str | os.PathLike, header: str = "") -> None:
    """Write ``scene`` to the TOML file ``path`` (see :func:`dumps_scene`; nothing is written
    when the text does not read back to the scene)."""
    text = dumps_scene(scene, header)
    try:
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text)
    except OSError as exc:  # one line naming the path, as every input problem
        raise SceneError(f"cannot write the scene to {path}: {exc.strerror or exc}", "path") from None
