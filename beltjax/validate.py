"""The checks every path into the model passes: a scene file, a parameter set with
:mod:`beltjax.parameters`, a sweep case and the Python API.

One table of the drive's numbers (``belt.EA``, ``pulley.<name>.center.x``, ``torque[0].mean_Nm``,
...; numpy arrays with one value per case) is checked, vectorised over the cases, for

* ``invalid_value``: a number outside its :mod:`beltjax.schema` range, a centre-of-mass
  offset outside its pulley, a tensioner arm's centre of mass beyond the arm;
* ``overlap``: two pulleys overlap, or the belt has no tangent from one to the next;
* ``no_belt_path``: a wrap angle degenerates, a span runs through a pulley or two spans cross
  (the rules of :func:`beltjax.geometry.check_drive`);
* ``ill_conditioned``: the derived float64 limits of :mod:`beltjax.schema` (a pinched span,
  an axial stiffness that swamps the string stiffness, bending that swamps the axial
  stiffness, a drive far from the origin).

A tensioner's idler is placed at ``tensioner.arm_angle_deg`` when given; otherwise only the
fixed pulleys are checked against each other (the arm angle is solved by the statics).
:func:`scene_problem` gives the first problem of a concrete scene as (key, message) with the
scene file's keys; :func:`case_status` gives every case's status (sweeps).  Traced scenes
(under jit, vmap or grad) are not checked.
"""

from __future__ import annotations

import math

import jax
import numpy as np

from beltjax import schema
from beltjax.errors import BeltjaxError
from beltjax.geometry import MIN_WRAP
from beltjax.scene import TENSIONER, Scene, SceneError, require_scene
from beltjax.scene.spec import drive_pulley_index

#: the statuses this module gives, in order of precedence ("ok" when none)
STATUSES = ("invalid_value", "overlap", "no_belt_path", "ill_conditioned")
_PULLEY_SCALARS = ("radius", "mass", "inertia", "speed_rpm", "acceleration_rpm_per_s", "fluctuation_amplitude_deg",
                   "fluctuation_frequency_hz", "bearing_damping", "target_speed_rpm")
_TENSIONER_SCALARS = ("arm_length", "pulley_radius", "arm_mass", "arm_inertia", "pulley_mass", "pulley_inertia",
                      "spring_stiffness", "spring_preload_deg", "arm_angle_deg", "arm_cm_distance", "damping")
_LOAD_SCALARS = {"torque": ("mean_Nm", "amplitude_Nm", "frequency_hz", "phase_deg", "t_start_s", "t_end_s"),
                 "span_load": ("amplitude_N", "frequency_hz", "phase_deg", "t_start_s", "t_end_s")}


def drive_pulley_name(scene: Scene) -> str:
    """The pulley whose speed sets the belt's: the (first) driven one, else the first in the file."""
    return scene.pulleys[drive_pulley_index(scene.pulleys)].name


def is_traced(scene) -> bool:
    """Whether any leaf of ``scene`` is a JAX tracer (inside jit, vmap or grad)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(scene))


# --------------------------------------------------------------------------- the table


def table(scene: Scene, values=None) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """({parameter path: values}, {parameter path: scene-file key}) of every scalar of ``scene``,
    with ``values`` {path: (n,) values} in place of the scene's (the belt switches to the key
    they give, as :func:`beltjax.parameters.set_value` does)."""
    t: dict[str, object] = {}
    keys: dict[str, str] = {}

    def put(path, key, x):
        if x is not None:
            t[path], keys[path] = x, key

    for k in ("EA", "EI", "rhoA", "CA", "static_tension", "length"):
        put(f"belt.{k}", f"belt.{k}", getattr(scene.belt, k))
    for i, p in enumerate(scene.pulleys):
        for v in ("center", "cm_offset"):
            for j, c in enumerate("xy"):
                put(f"pulley.{p.name}.{v}.{c}", f"pulley[{i}].{v}", np.asarray(getattr(p, v))[j])
        for k in _PULLEY_SCALARS:
            put(f"pulley.{p.name}.{k}", f"pulley[{i}].{k}", getattr(p, k))
    if scene.tensioner is not None:
        for j, c in enumerate("xy"):
            put(f"tensioner.pivot.{c}", "tensioner.pivot", np.asarray(scene.tensioner.pivot)[j])
        for k in _TENSIONER_SCALARS:
            put(f"tensioner.{k}", f"tensioner.{k}", getattr(scene.tensioner, k))
    for group, loads in (("torque", scene.torques), ("span_load", scene.span_loads)):
        for i, load in enumerate(loads):
            for k in _LOAD_SCALARS[group]:
                put(f"{group}[{i}].{k}", f"{group}[{i}].{k}", getattr(load, k))
    sim = scene.simulation
    for k in ("dt_s", "rho_inf", "rtol", "atol", "output_dt_s"):
        put(f"simulation.{k}", f"simulation.{k}", getattr(sim, k))
    for name, deg in scene.initial.rotation_deg:
        put(f"initial.rotation_deg.{name}", f"initial.rotation_deg.{name}", deg)
    put("initial.arm_angle_deg", "initial.arm_angle_deg", scene.initial.arm_angle_deg)
    if values:
        for path in values:
            if path in ("belt.length", "belt.static_tension"):
                t.pop("belt.static_tension" if path == "belt.length" else "belt.length", None)
            keys.setdefault(path, path)
        t.update(values)
    return {k: np.asarray(v, dtype=float) for k, v in t.items()}, keys


# --------------------------------------------------------------------------- the checks


def _ranges(scene: Scene, t, keys):
    """[(status, bad (n,), describe(case) -> (key, message))] of the value checks."""
    out = []
    for path, v in t.items():
        f = schema.field(path if not path.startswith("initial.rotation_deg.") else "initial.rotation_deg")
        if f is not None:
            out.append(("invalid_value", schema.bad(f, v),
                        lambda c, f=f, v=v, path=path: (keys[path], schema.problem(f, _at(v, c)))))
    for name in [p.name for p in scene.pulleys]:
        off = np.hypot(t[f"pulley.{name}.cm_offset.x"], t[f"pulley.{name}.cm_offset.y"])
        R = t[f"pulley.{name}.radius"]
        out.append(("invalid_value", off >= R, lambda c, off=off, R=R, name=name: (
            keys[f"pulley.{name}.cm_offset.x"],
            f"offset {_at(off, c)!r} m must be smaller than the radius {_at(R, c)!r} m")))
    name = drive_pulley_name(scene)
    speed = schema.FIELDS["drive.speed"]
    for k in ("speed_rpm", "target_speed_rpm"):
        if f"pulley.{name}.{k}" in t:
            rpm, R = t[f"pulley.{name}.{k}"], t[f"pulley.{name}.radius"]
            v = np.abs(rpm) * (2 * np.pi / 60) * R
            out.append(("invalid_value", v > speed.high, lambda c, k=k, v=v, R=R: (
                keys[f"pulley.{name}.{k}"], f"gives the belt {_at(v, c):.6g} m/s on the radius {_at(R, c):g} m, "
                f"beyond {speed.high:g} m/s ({speed.why})")))
    if "tensioner.arm_cm_distance" in t:
        cm, arm = t["tensioner.arm_cm_distance"], t["tensioner.arm_length"]
        out.append(("invalid_value", cm > arm, lambda c: (
            "tensioner.arm_cm_distance",
            f"must not exceed arm_length = {_at(arm, c)!r}, got {_at(cm, c)!r}")))
    return out


def _layout(scene: Scene, t):
    """(entries, names, centres (n, k, 2), radii (n, k), senses (k,), full route?) in route order;
    the idler only when its arm angle is known."""
    order = scene.route.order
    full = scene.tensioner is None or "tensioner.arm_angle_deg" in t
    entries = [i for i, name in enumerate(order) if full or name != TENSIONER]
    C, R = [], []
    for i in entries:
        name = order[i]
        if name == TENSIONER:
            th = np.deg2rad(t["tensioner.arm_angle_deg"])
            a = t["tensioner.arm_length"]
            C.append(np.stack(np.broadcast_arrays(t["tensioner.pivot.x"] + a * np.cos(th),
                                                  t["tensioner.pivot.y"] + a * np.sin(th)), -1))
            R.append(t["tensioner.pulley_radius"])
        else:
            C.append(np.stack(np.broadcast_arrays(t[f"pulley.{name}.center.x"], t[f"pulley.{name}.center.y"]), -1))
            R.append(t[f"pulley.{name}.radius"])
    n = max(np.size(x) for x in t.values())
    C = np.stack([np.broadcast_to(c.reshape(-1, 2), (n, 2)) for c in C], 1)
    R = np.stack([np.broadcast_to(r.reshape(-1), (n,)) for r in R], 1)
    return entries, [order[i] for i in entries], C, R, np.asarray(scene.route.senses)[entries], full


def _at(x, c: int) -> float:
    """Case ``c`` of ``x`` (a scalar broadcast to every case)."""
    x = np.ravel(x)
    return float(x[c] if x.size > 1 else x[0])


def _perp(v):
    return np.stack([-v[..., 1], v[..., 0]], -1)


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _geometry_checks(scene: Scene, t):
    """The layout checks and the derived float64 limits (see the module docstring)."""
    entries, names, C, R, s, full = _layout(scene, t)
    k = len(entries)
    file_index = {p.name: i for i, p in enumerate(scene.pulleys)}

    def key_of(*idx):
        if any(names[i] == TENSIONER for i in idx):
            return "tensioner.arm_angle_deg"
        i = max(idx, key=lambda i: file_index[names[i]])
        return f"pulley[{file_index[names[i]]}].center"

    v = _at
    out = []
    scale = np.maximum(1.0, np.maximum(np.max(np.abs(C), axis=(1, 2)), np.max(R, axis=1)))
    tol = 1e-12 * scale
    D = {}
    for i in range(k):
        for j in range(k):
            D[i, j] = np.hypot(*(C[:, j] - C[:, i]).T)
    if full:
        for i in range(k):
            j = (i + 1) % k
            crossed = s[i] != s[j]
            need = R[:, i] + R[:, j] if crossed else np.abs(R[:, i] - R[:, j])
            out.append(("overlap", D[i, j] <= need + tol, lambda c, i=i, j=j, need=need, crossed=crossed: (
                key_of(i, j), f"no {'crossed' if crossed else 'open'} tangent from {names[i]!r} to {names[j]!r}: "
                f"centre distance {v(D[i, j], c):.6g} m <= {'R1 + R2' if crossed else '|R1 - R2|'} = "
                f"{v(need, c):.6g} m")))
    for i in range(k):
        for j in range(i + 1, k):
            out.append(("overlap", D[i, j] <= R[:, i] + R[:, j] + tol, lambda c, i=i, j=j: (
                key_of(i, j), f"pulleys {names[i]!r} and {names[j]!r} overlap: centre distance {v(D[i, j], c):.6g} m "
                f"<= R1 + R2 = {v(R[:, i] + R[:, j], c):.6g} m")))
    lengths = [R[:, i] for i in range(k)]
    if scene.tensioner is not None:
        lengths.append(np.broadcast_to(t["tensioner.arm_length"].reshape(-1), R[:, 0].shape))
    if full:
        nxt = (np.arange(k) + 1) % k
        r1, r2 = s * R, s[nxt] * R[:, nxt]
        d = C[:, nxt] - C
        Dn = np.hypot(d[..., 0], d[..., 1])
        rr = r1 - r2
        L = np.sqrt(np.maximum(Dn**2 - rr**2, 0.0))
        e = d / Dn[..., None]
        tan = (L[..., None] * e + rr[..., None] * _perp(e)) / Dn[..., None]
        m = _perp(tan)
        start, end = C - r1[..., None] * m, C[:, nxt] - r2[..., None] * m
        t_in = np.roll(tan, 1, axis=1)
        wrap = np.mod(s * np.arctan2(_cross(t_in, tan), np.sum(t_in * tan, -1)), 2 * np.pi)
        for i in range(k):
            w = wrap[:, i]
            out.append(("no_belt_path", ~((w > MIN_WRAP) & (w < 2 * np.pi - MIN_WRAP)), lambda c, i=i, w=w: (
                "route.order", f"wrap angle on pulley {names[i]!r} degenerates: {math.degrees(v(w, c)) + 0.0:.6g} deg "
                "(the belt only grazes it, or would loop round it)")))
        for i in range(k):
            a, b = start[:, i], end[:, i]
            ab = b - a
            den = np.sum(ab * ab, -1)
            for q in range(k):
                if q in (i, (i + 1) % k):
                    continue
                u = np.clip(np.sum((C[:, q] - a) * ab, -1) / np.where(den == 0, 1.0, den), 0.0, 1.0)
                dist = np.hypot(*(C[:, q] - (a + u[:, None] * ab)).T)
                out.append(("no_belt_path", dist < R[:, q] - tol, lambda c, i=i, q=q: (
                    "route.order", f"span {names[i]!r} -> {names[(i + 1) % k]!r} passes through pulley {names[q]!r}")))
        if k > 2:
            for i in range(k):
                for j in range(i + 1, k):
                    a, b, p, q = start[:, i], end[:, i], start[:, j], end[:, j]
                    o1, o2 = _cross(b - a, p - a), _cross(b - a, q - a)
                    o3, o4 = _cross(q - p, a - p), _cross(q - p, b - p)
                    bad = (o1 * o2 < -tol * tol) & (o3 * o4 < -tol * tol)
                    out.append(("no_belt_path", bad, lambda c, i=i, j=j: (
                        "route.order", f"spans {names[i]!r} -> {names[(i + 1) % k]!r} and {names[j]!r} -> "
                        f"{names[(j + 1) % k]!r} cross each other (check route.order and back_side)")))
        out += _derived(scene, t, names, L, key_of)
        lengths += [L[:, i] for i in range(k)]
    out += _offset(scene, t, C, lengths, entries, file_index)
    return out


def _derived(scene: Scene, t, names, L, key_of):
    """The derived float64 limits on the spans (module doc of :mod:`beltjax.schema`)."""
    k = len(names)
    EA, EI = t["belt.EA"], t["belt.EI"]
    ancf = scene.model.fidelity == "ancf"
    N = scene.model.elements_per_span if ancf else 1
    lo, hi = np.argmin(L, axis=1), np.argmax(L, axis=1)
    rows = np.arange(L.shape[0])
    Lmin, Lmax = L[rows, lo], L[rows, hi]

    def stiff(Le):
        return schema.element_stiffness(EA, EI, Le, ancf)

    with np.errstate(all="ignore"):
        spread = stiff(Lmin / N) / stiff(Lmax / N)
    span = [f"{names[i]}-{names[(i + 1) % k]}" for i in range(k)]
    out = [("ill_conditioned", ~(spread <= schema.MAX_SPAN_SPREAD), lambda c: (
        key_of(int(lo[c]), (int(lo[c]) + 1) % k),
        f"span {span[lo[c]]} is {float(Lmin[c]):.3g} m long beside span {span[hi[c]]} of {float(Lmax[c]):.3g} m: "
        f"its elements are {float(spread[c]):.3g} times stiffer (at most {schema.MAX_SPAN_SPREAD:g}), beyond what "
        "float64 eigen-solves resolve beside the long spans (move the pulleys apart)"))]
    if not ancf:
        return out
    with np.errstate(all="ignore"):
        Le_min = Lmin / N
        bending = EI / (EA * Le_min**2)
    out.append(("ill_conditioned", ~(bending <= schema.MAX_BENDING_RATIO), lambda c: (
        "belt.EI", f"EI / (EA Le^2) = {_at(bending, c):.3g} on span {span[lo[c]]} ({N} elements of "
        f"{float(Le_min[c]):.3g} m), above {schema.MAX_BENDING_RATIO:g}: bending swamps the axial stiffness in "
        "float64 (a rod, not a belt: check EI's unit, or use fewer elements per span)")))
    if "belt.static_tension" in t:
        T = t["belt.static_tension"]
        string = schema.string_spread(EA, EI, T, Lmax, N)
        out.append(("ill_conditioned", ~(string <= schema.MAX_STRING_SPREAD), lambda c: (
            "belt.EA", f"the axial stiffness ({_at(EA, c):g} N over {N} elements per span) is "
            f"{float(string[c]):.3g} times the string stiffness of span {span[hi[c]]} at tension {_at(T, c):g} N "
            f"(at most {schema.MAX_STRING_SPREAD:g}), beyond what float64 eigen-solves resolve (check EA's unit, or "
            "use fewer elements per span)")))
    return out


def _offset(scene: Scene, t, C, lengths, entries, file_index):
    """The farthest centre from the origin against the drive's smallest length."""
    pts = [C[:, i] for i in range(C.shape[1])]
    keys = [f"pulley[{file_index[scene.route.order[i]]}].center" if scene.route.order[i] != TENSIONER
            else "tensioner.arm_angle_deg" for i in entries]
    if scene.tensioner is not None:
        pts.append(np.stack(np.broadcast_arrays(t["tensioner.pivot.x"], t["tensioner.pivot.y"]), -1).reshape(-1, 2))
        keys.append("tensioner.pivot")
    dist = np.stack([np.broadcast_to(np.hypot(p[:, 0], p[:, 1]), C.shape[:1]) for p in pts], 1)
    small = np.min(np.stack([np.broadcast_to(x, C.shape[:1]) for x in lengths], 1), axis=1)
    far = np.argmax(dist, axis=1)
    with np.errstate(all="ignore"):
        ratio = dist[np.arange(dist.shape[0]), far] / small
    return [("ill_conditioned", ~(ratio <= schema.MAX_OFFSET_RATIO), lambda c: (
        keys[far[c]], f"{float(dist[c, far[c]]):.3g} m from the origin, {float(ratio[c]):.3g} times the drive's "
        f"smallest length ({float(small[c]):.3g} m; at most {schema.MAX_OFFSET_RATIO:g}): float64 round-off of the "
        "tangent geometry would swamp the belt's stretch (put the origin near the drive)"))]


def _checks(scene: Scene, values=None):
    t, keys = table(scene, values)
    yield from _ranges(scene, t, keys)
    with np.errstate(all="ignore"):
        yield from _geometry_checks(scene, t)


# --------------------------------------------------------------------------- entry points


def scene_problem(scene: Scene) -> tuple[str, str] | None:
    """The first problem of a concrete scene as (scene-file key, message), or None (also for a
    traced scene)."""
    if is_traced(scene):
        return None
    for _, bad, describe in _checks(scene):
        if np.ravel(bad)[0]:
            return describe(0)
    return None


def check_scene(scene: Scene) -> Scene:
    """``scene`` if it passes every check, else :class:`beltjax.scene.SceneError` (one line
    starting with the scene-file key, as the scene file's parser gives it)."""
    p = scene_problem(require_scene(scene))
    if p is not None:
        raise SceneError(p[1], p[0], source=scene.source)
    return scene


def case_status(scene: Scene, values, n: int) -> tuple[np.ndarray, dict[str, tuple[int, str]]]:
    """Vectorised checks of a case table {path: (n,) values} on ``scene``: ((n,) status names,
    "ok" where every check passes; {status: (first case, its one-line message)})."""
    return _statuses(list(_checks(scene, values)), n, STATUSES)


def solved_status(scene: Scene, tension_N, arm_angle_deg=None, values=None, n: int = 1
                  ) -> tuple[np.ndarray, dict[str, tuple[int, str]]]:
    """The checks that need the solved installation, run again with it: the layout with a
    tensioner's arm at its equilibrium ``arm_angle_deg`` (deg; the scene's ``arm_angle_deg`` is
    only Newton's guess) and the string-spread limit at the installation tension ``tension_N``
    (N; a belt given by its length has no tension before the statics).  Scalars or (n,) arrays,
    one per case of ``values``; statuses "overlap", "no_belt_path", "ill_conditioned".  Returns
    what :func:`case_status` returns."""
    vals = dict(values or {})
    vals["belt.static_tension"] = np.broadcast_to(np.asarray(tension_N, dtype=float), (n,))
    if scene.tensioner is not None and arm_angle_deg is not None:
        vals["tensioner.arm_angle_deg"] = np.broadcast_to(np.asarray(arm_angle_deg, dtype=float), (n,))
    t, _ = table(scene, vals)
    with np.errstate(all="ignore"):
        checks = [c for c in _geometry_checks(scene, t) if c[0] != "invalid_value"]
    return _statuses(checks, n, ("overlap", "no_belt_path", "ill_conditioned"))


def _statuses(checks, n: int, names) -> tuple[np.ndarray, dict[str, tuple[int, str]]]:
    status = np.full(n, "ok", dtype=object)
    first: dict[str, tuple[int, str]] = {}
    for name in names:
        for st, bad, describe in checks:
            if st != name:
                continue
            b = np.broadcast_to(np.ravel(bad), (n,)) & (status == "ok")
            if b.any():
                c = int(np.argmax(b))
                status[b] = name
                first.setdefault(name, (c, "{}: {}".format(*describe(c if np.size(bad) > 1 else 0))))
    return status, first


def speeds(values, key: str = "rpm", field: str = "drive.rpm") -> np.ndarray:
    """A non-empty 1-D array of speeds, each in the range of ``field`` (NaN, infinite and
    negative speeds are errors naming ``key[i]``)."""
    try:
        v = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise BeltjaxError(f"expected an array of numbers, got {values!r}", key) from None
    if v.size == 0:
        raise BeltjaxError("expected at least one speed", key)
    bad = schema.bad(schema.FIELDS[field], v)
    if bad.any():
        i = int(np.argmax(bad))
        raise BeltjaxError(schema.problem(schema.FIELDS[field], v[i]), f"{key}[{i}]")
    return v


class RangeError(ValueError):
    """A speed range A:B:STEP that :func:`rpm_range` refuses; ``part``: 0, 1 or 2 for the value
    at fault (A, B or STEP), None for the range as a whole (too many speeds)."""

    def __init__(self, msg: str, part: int | None):
        super().__init__(msg)
        self.part = part


def rpm_range(a: float, b: float, step: float, max_speeds: int) -> np.ndarray:
    """The speeds (rpm) of a range A:B:STEP: A, A + STEP, ... up to B, and B itself, never beyond
    it (the last step shorter where STEP does not divide B - A; an end within 1e-9 STEP of a grid
    point is that point).  The one reading of ``--rpm`` and of a sweep's ``rpm``: a value not
    finite, STEP <= 0, A < 0, B < A or more than ``max_speeds`` speeds is a :class:`RangeError`
    saying which (before any array is made); the callers name their own key."""
    for i, (x, name) in enumerate(((a, "start A"), (b, "end B"), (step, "STEP"))):
        if not math.isfinite(x):
            raise RangeError(f"{name} must be finite, got {x!r}", i)
    if step <= 0:
        raise RangeError(f"STEP must be > 0, got {step!r}", 2)
    if a < 0:
        raise RangeError(f"start A must be >= 0, got {a!r}", 0)
    if b < a:
        raise RangeError(f"end B must be >= start A, got {b!r}", 1)
    k = math.floor((b - a) / step + 1e-9)  # whole steps from A to at most B
    on_grid = abs(b - (a + k * step)) <= 1e-9 * step
    n = k + 1 + (not on_grid)
    if n > max_speeds:
        raise RangeError(f"gives {n} speeds, at most {max_speeds} allowed", None)
    r = a + step * np.arange(k + 1, dtype=float)
    return np.append(r[:-1] if on_grid else r, b)


def count(value, key: str) -> int:
    """``value`` as an int if it is an integer >= 1 (a bool is not), else a one-line
    :class:`BeltjaxError` naming ``key`` (an API argument: modes kept, cases per chunk, ...)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise BeltjaxError(f"must be an integer >= 1, got {value!r}", key)
    return int(value)


def positive(value, key: str, what: str = "number", unit: str = "", upper: float = math.inf) -> float:
    """``value`` as a float if it is a finite number > 0 (and at most ``upper``; an API argument:
    a tolerance, a time in s), else a one-line :class:`BeltjaxError` naming ``key`` and saying
    ``what`` it is (with its ``unit``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise BeltjaxError(f"expected a number, got {value!r}", key) from None
    if not (math.isfinite(v) and 0 < v <= upper):
        bound = f" and at most {upper:g}{unit}" if upper < math.inf else ""
        raise BeltjaxError(f"must be a finite {what} > 0{unit}{bound}, got {value!r}", key)
    return v


def interval(value, key: str) -> float:
    """:func:`positive` for a time (s): an output interval, a chunk's length."""
    return positive(value, key, "time", " s")


def flag(value, key: str, allow_none: bool = False) -> bool | None:
    """``value`` if it is a bool (or None where ``allow_none``), else a one-line
    :class:`BeltjaxError` naming ``key`` (an API switch: a string "no" would be true)."""
    if isinstance(value, (bool, np.bool_)) or (allow_none and value is None):
        return value if value is None else bool(value)
    raise BeltjaxError(f"must be True or False{' or None' if allow_none else ''}, got {value!r}", key)
