"""Scene parameters addressed by name: one mechanism for sweeps, fits and layout optimisation.

A parameter path names one scalar leaf of a :class:`beltjax.scene.Scene` with the keys of the
scene file::

    belt.EA  belt.EI  belt.rhoA  belt.CA  belt.static_tension  belt.length
    pulley.<name>.center.x  pulley.<name>.center.y  pulley.<name>.radius  pulley.<name>.mass
    pulley.<name>.inertia  pulley.<name>.speed_rpm  pulley.<name>.bearing_damping ...
    tensioner.pivot.x  tensioner.pivot.y  tensioner.arm_length  tensioner.spring_stiffness
    tensioner.spring_preload_deg  tensioner.damping ...

Units are those of the scene file (SI; ``_deg`` degrees, ``_rpm`` rpm).  :func:`set_value`
returns a new scene (pure, so it runs under ``jit``, ``vmap`` and ``grad``: gradients reach
any parameter).  The belt is given by exactly one of ``static_tension`` and ``length``;
setting the other one switches the scene to it (the installation then solves for the first).
A path that names nothing is a :class:`ParameterError` naming the path and the choices, and
so is a speed of a pulley that is not the drive pulley (only the drive pulley takes a speed,
and only a driven pulley a prescribed acceleration or fluctuation: the scene file's rule).

With concrete values (not under ``jit``, ``vmap`` or ``grad``) :func:`set_value` and
:func:`set_values` check the new scene as a scene file is checked: each value against its
:mod:`beltjax.schema` range, and the whole drive with :func:`beltjax.validate.scene_problem`
(overlapping pulleys, degenerate wraps, the derived float64 limits); a problem is a
:class:`ParameterError` naming the path, e.g. ``belt.EI: must lie in [0, 100000] N m^2 (...),
got 1e+20``.  Traced values are never checked (no Python branching on them).
"""

from __future__ import annotations

import dataclasses

from typing import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import schema, validate
from beltjax.errors import BeltjaxError
from beltjax.scene import Scene
from beltjax.drive.effects import effects_of

_COMPONENTS = {"x": 0, "y": 1}
_VECTORS = {"pulley": ("center", "cm_offset"), "tensioner": ("pivot",)}
_BELT = ("EA", "EI", "rhoA", "CA", "static_tension", "length", "friction_coefficient", "groove_angle_deg",
         "slip_speed")
_PULLEY = ("radius", "mass", "inertia", "speed_rpm", "acceleration_rpm_per_s",
           "fluctuation_amplitude_deg", "fluctuation_frequency_hz", "bearing_damping", "friction_coefficient")
#: keys a scene may leave out (no value to sweep or fit unless given)
_OPTIONAL = ("friction_coefficient", "groove_angle_deg", "stop_min_deg", "stop_max_deg", "stop_stiffness")
#: pulley keys of the drive pulley only (its speed) and of driven pulleys only (prescribed motion)
_DRIVE_ONLY = ("speed_rpm",)
_DRIVEN_ONLY = ("acceleration_rpm_per_s", "fluctuation_amplitude_deg", "fluctuation_frequency_hz")
_TENSIONER = ("arm_length", "pulley_radius", "arm_mass", "arm_inertia", "pulley_mass",
              "pulley_inertia", "spring_stiffness", "spring_preload_deg", "arm_cm_distance", "damping",
              "friction_moment", "friction_asymmetry", "friction_speed", "friction_stick_time", "stop_min_deg", "stop_max_deg",
              "stop_stiffness")


_DECOUPLER = ("rotor_inertia", "stiffness", "damping")
_ISOLATOR = ("stiffness", "damping")


class ParameterError(BeltjaxError):
    """A parameter path that names no scalar of the scene, or a value out of its range (one line)."""

    @property
    def path(self) -> str:
        """The parameter path the message is about (the ``key``)."""
        return self.key

    def quoted(self, path: str) -> str:
        """The message about ``path``, the path quoted (repr) when it holds white space or a
        character that would not show (" belt.EA" would read as belt.EA)."""
        msg = str(self)
        if path.isprintable() and not any(c.isspace() for c in path):
            return msg
        return f"{path!r}: {msg[len(path) + 1:].strip()}" if msg.startswith(f"{path}:") else msg


def _motion_rule(scene: Scene, name: str, key: str) -> str | None:
    """Why pulley ``name`` cannot take the prescribed-motion ``key``, or None."""
    drive = validate.drive_pulley_name(scene)
    if key in _DRIVE_ONLY and name != drive:
        return (f"only the drive pulley takes a speed: a driven pulley (driven = true), else the first pulley "
                f"(here {drive!r})")
    if key in _DRIVEN_ONLY and not scene.pulley(name).driven:
        return "only a driven pulley (driven = true) takes a prescribed motion"
    return None


def paths(scene: Scene) -> list[str]:
    """Every scalar parameter path of ``scene`` (see the module docstring): a speed only on the
    drive pulley, an acceleration or fluctuation only on driven pulleys, an optional key
    (friction coefficients, groove angle) only where the scene gives it."""
    b = scene.belt
    out = [f"belt.{k}" for k in _BELT if k not in _OPTIONAL or getattr(b, k) is not None]
    for p in scene.pulleys:
        out += [f"pulley.{p.name}.{v}.{c}" for v in _VECTORS["pulley"] for c in _COMPONENTS]
        out += [f"pulley.{p.name}.{k}" for k in _PULLEY if _motion_rule(scene, p.name, k) is None
                and (k not in _OPTIONAL or getattr(p, k) is not None)]
    out += [f"decoupler.{d.pulley}.{k}" for d in scene.decouplers for k in _DECOUPLER]
    out += [f"isolator.{k}" for k in _ISOLATOR] if scene.isolator is not None else []
    if scene.tensioner is not None:
        out += [f"tensioner.pivot.{c}" for c in _COMPONENTS]
        t = scene.tensioner
        stops = t.stop_min_deg is not None or t.stop_max_deg is not None
        out += [f"tensioner.{k}" for k in _TENSIONER
                if k not in _OPTIONAL or (getattr(t, k) is not None and (k != "stop_stiffness" or stops))]
    return out


def _resolve(scene: Scene, path: str):
    """(getter of the owning array leaf, component index or None, field) for ``path``."""
    if not isinstance(path, str) or not path:
        raise ParameterError("a parameter path is a non-empty string such as 'belt.EI'", str(path))
    parts = path.split(".")
    head = parts[0]
    if head == "belt":
        if len(parts) != 2 or parts[1] not in _BELT:
            raise ParameterError(f"belt parameters are {', '.join('belt.' + k for k in _BELT)}", path)
        return (lambda s: s.belt), None, parts[1]
    if head == "pulley":
        names = [p.name for p in scene.pulleys]
        if len(parts) < 3 or parts[1] not in names:
            raise ParameterError(f"write pulley.<name>.<key> with a pulley of the scene ({', '.join(names)})", path)
        i = names.index(parts[1])
        rest, owner, vectors, scalars = parts[2:], (lambda s: s.pulleys[i]), _VECTORS["pulley"], _PULLEY
    elif head == "tensioner":
        if scene.tensioner is None:
            raise ParameterError("the scene has no tensioner", path)
        rest, owner, vectors, scalars = parts[1:], (lambda s: s.tensioner), _VECTORS["tensioner"], _TENSIONER
    elif head == "isolator":
        if scene.isolator is None:
            raise ParameterError("the scene has no isolator", path)
        rest, owner, vectors, scalars = parts[1:], (lambda s: s.isolator), (), _ISOLATOR
    elif head == "decoupler":
        names = [d.pulley for d in scene.decouplers]
        if len(parts) < 3 or parts[1] not in names:
            raise ParameterError(f"write decoupler.<pulley>.<key> with a decoupled pulley of the scene "
                                 f"({', '.join(names) or 'none'})", path)
        i = names.index(parts[1])
        rest, owner, vectors, scalars = parts[2:], (lambda s: s.decouplers[i]), (), _DECOUPLER
    else:
        raise ParameterError("a parameter path starts with belt., pulley.<name>., tensioner., isolator. or "
                             "decoupler.<pulley>.", path)
    if len(rest) == 2 and rest[0] in vectors and rest[1] in _COMPONENTS:
        return owner, _COMPONENTS[rest[1]], rest[0]
    if len(rest) == 1 and rest[0] in scalars:
        why = _motion_rule(scene, parts[1], rest[0]) if head == "pulley" else None
        if why is not None:
            raise ParameterError(why, path)
        return owner, None, rest[0]
    keys = [f"{v}.{c}" for v in vectors for c in _COMPONENTS] + list(scalars)
    raise ParameterError(f"unknown key {'.'.join(rest)!r}; choose one of {', '.join(keys)}", path)


def check(scene: Scene, path: str) -> str:
    """``path`` if it names a scalar of ``scene`` that can be set and that acts: its owning
    effect (:data:`beltjax.schema.FIELDS`), if any, is listed in ``model.effects`` (else
    :class:`ParameterError`: a sweep or fit of a parameter that changes nothing)."""
    owner, _, name = _resolve(scene, path)
    if owner(scene) is None:
        raise ParameterError("the scene has no such part", path)
    if name not in ("static_tension", "length") and getattr(owner(scene), name) is None:
        raise ParameterError("this parameter is not set in the scene (give it in the scene file first)", path)
    f = schema.field(path)
    if f is not None and f.effect and f.effect not in effects_of(scene):
        raise ParameterError(f"belongs to the effect \"{f.effect}\", which model.effects does not list: it "
                             "would change nothing", path)
    return path


def check_value(path: str, value) -> None:
    """:class:`ParameterError` if a concrete ``value`` lies outside the range of ``path``
    (:mod:`beltjax.schema`); nothing for a traced value."""
    if isinstance(value, jax.core.Tracer):
        return
    f = schema.field(path)
    if f is not None and isinstance(value, int) and not isinstance(value, bool) and abs(value) > 2**1023:
        raise ParameterError(schema.problem(f, value), path)  # beyond float64
    v = np.ravel(np.asarray(value, dtype=float))
    if f is not None and v.size:
        bad = schema.bad(f, v)
        if bad.any():
            raise ParameterError(schema.problem(f, v[int(np.argmax(bad))]), path)


def _concrete(values: Mapping[str, object]) -> bool:
    return not any(isinstance(v, jax.core.Tracer) for v in values.values())


def _checked(scene: Scene, values: Mapping[str, object]) -> Scene:
    """``scene`` (with ``values`` set, each already checked by :func:`check_value`) if it passes
    the scene file's checks of the whole drive; concrete values only."""
    if not _concrete(values) or validate.is_traced(scene):
        return scene
    if any(np.ndim(v) for v in values.values()):
        return scene  # a batch of values: checked case by case by beltjax.validate.case_status
    problem = validate.scene_problem(scene)
    if problem is not None:
        key, msg = problem
        _, keys = validate.table(scene)
        blame = next((p for p in values if keys.get(p) == key), next(iter(values)))
        raise ParameterError(msg if keys.get(blame) == key else f"{key}: {msg}", blame)
    return scene


def get_value(scene: Scene, path: str):
    """The scalar at ``path`` (file units).  The belt parameter that the scene does not give
    (``length`` or ``static_tension``) is NaN here: it is solved by the installation."""
    owner, comp, name = _resolve(scene, path)
    x = getattr(owner(scene), name)
    if x is None:
        return jnp.asarray(jnp.nan)
    x = jnp.asarray(x)
    return x[comp] if comp is not None else x


def set_value(scene: Scene, path: str, value) -> Scene:
    """A copy of ``scene`` with the scalar at ``path`` set to ``value`` (file units; traceable).

    A concrete value is checked with the new scene (see the module docstring)."""
    check_value(path, value)
    return _checked(_set(scene, path, value), {path: value})


def _set(scene: Scene, path: str, value) -> Scene:
    owner, comp, name = _resolve(scene, path)
    value = jnp.asarray(value, dtype=jnp.float64)
    if name in ("static_tension", "length"):
        other = "length" if name == "static_tension" else "static_tension"
        return eqx.tree_at(lambda s: s.belt, scene, dataclasses.replace(scene.belt, **{name: value, other: None}))
    leaf = getattr(owner(scene), name)
    if leaf is None:
        raise ParameterError("this parameter is not set in the scene (give it in the scene file first)", path)
    new = jnp.asarray(leaf, dtype=jnp.float64).at[comp].set(value) if comp is not None else value
    return eqx.tree_at(lambda s: getattr(owner(s), name), scene, new)


def set_values(scene: Scene, values: Mapping[str, object]) -> Scene:
    """``scene`` with several parameters set: {path: value} (file units; traceable); concrete
    values are checked together, with the new scene (see the module docstring)."""
    for path, value in values.items():
        check_value(path, value)
    for path, value in values.items():
        scene = _set(scene, path, value)
    return _checked(scene, values) if values else scene


def unit(path: str) -> str:
    """The unit of the parameter at ``path`` as the scene file gives it (e.g. "m", "N m^2"),
    "" for a path that names no known parameter (:mod:`beltjax.schema`)."""
    f = schema.field(str(path))
    return f.unit if f is not None else ""
