"""Readers of the scene file's tables, one per section ([belt], [[pulley]], [tensioner], [route],
[model], [[torque]], [[span_load]], [initial], [simulation]): key sets, types and ranges."""

from __future__ import annotations

import functools
import math

import jax.numpy as jnp

from beltjax import schema, tomltable
from beltjax.ancf import BENDING_MODELS
from beltjax.tomltable import describe
from beltjax.scene.spec import ARM, Belt, DIRECTIONS, EFFECTS, FIDELITIES, Initial, MAX_ELEMENTS_PER_SPAN, Model, Pulley, Route, SOLVERS, Scene, SceneError, Simulation, SpanLoad, TENSIONER, Tensioner, Torque, Decoupler, Isolator


def _fail(key, msg, source=""):
    raise SceneError(msg, key, source=source)


def _table(data, key: str, source: str, allowed: tuple[str, ...]) -> tomltable.Table:
    """A scene table being read (errors: :class:`SceneError` naming ``source``)."""
    return tomltable.Reader(functools.partial(_fail, source=source)).table(data, key, allowed)


def _arr(x):
    return None if x is None else jnp.asarray(x, dtype=jnp.float64)


_num = schema.read_number


_vec = schema.read_vector


_D = schema.default


_TOP_KEYS = (
    "description", "belt", "pulley", "tensioner", "route", "model", "fluctuation", "decoupler", "isolator", "torque",
    "span_load", "initial", "simulation"
)


_BELT_KEYS = ("EA", "EI", "rhoA", "static_tension", "length", "CA", "friction_coefficient", "groove_angle_deg",
              "slip_speed")


_PULLEY_KEYS = (
    "name",
    "center",
    "radius",
    "mass",
    "inertia",
    "driven",
    "speed_rpm",
    "acceleration_rpm_per_s",
    "fluctuation_amplitude_deg",
    "fluctuation_frequency_hz",
    "cm_offset",
    "bearing_damping",
    "target_speed_rpm",
    "friction_coefficient",
)


_DRIVEN_ONLY = ("acceleration_rpm_per_s", "fluctuation_amplitude_deg", "fluctuation_frequency_hz", "target_speed_rpm")


_TORQUE_KEYS = ("pulley", "mean_Nm", "amplitude_Nm", "frequency_hz", "phase_deg", "t_start_s", "t_end_s")


_SPAN_LOAD_KEYS = ("span", "node", "amplitude_N", "frequency_hz", "phase_deg", "t_start_s", "t_end_s")


_INITIAL_KEYS = ("rotation_deg", "arm_angle_deg")


_SIMULATION_KEYS = ("solver", "dt_s", "rho_inf", "rtol", "atol", "output_dt_s", "nodes", "max_steps")


_TENSIONER_KEYS = (
    "pivot",
    "arm_length",
    "pulley_radius",
    "arm_mass",
    "arm_inertia",
    "pulley_mass",
    "pulley_inertia",
    "spring_stiffness",
    "spring_preload_deg",
    "arm_angle_deg",
    "arm_cm_distance",
    "damping",
    "friction_moment",
    "friction_asymmetry",
    "friction_speed",
    "friction_stick_time",
    "stop_min_deg",
    "stop_max_deg",
    "stop_stiffness",
)


_ROUTE_KEYS = ("order", "back_side", "direction")


_MODEL_KEYS = ("fidelity", "elements_per_span", "effects", "bending")


def _parse_belt(data, source) -> Belt:
    t = _table(data, "belt", source, _BELT_KEYS)
    EA = _num(t, "EA", "belt")
    EI = _num(t, "EI", "belt")
    rhoA = _num(t, "rhoA", "belt")
    if t.has("static_tension") == t.has("length"):
        _fail("belt", "give exactly one of static_tension and length", source)
    T = _num(t, "static_tension", "belt", required=False)
    L = _num(t, "length", "belt", required=False)
    CA = _num(t, "CA", "belt", required=False)
    mu = _num(t, "friction_coefficient", "belt", required=False)
    groove = _num(t, "groove_angle_deg", "belt", required=False)
    slip = _num(t, "slip_speed", "belt", required=False)
    return Belt(EA=_arr(EA), EI=_arr(EI), rhoA=_arr(rhoA), static_tension=_arr(T), length=_arr(L), CA=_arr(CA),
                friction_coefficient=_arr(mu), groove_angle_deg=_arr(groove), slip_speed=_arr(slip))


def _parse_pulley(data, i, source) -> Pulley:
    t = _table(data, f"pulley[{i}]", source, _PULLEY_KEYS)
    name = t.string("name")
    if not name.strip():
        t.fail("name", "must not be empty")
    if not name.isprintable():  # a line break or control character would break every table it names
        t.fail("name", f"must be printable (no line breaks or control characters), got {name!r}")
    if name == TENSIONER:
        t.fail("name", f"{TENSIONER!r} is reserved for the [tensioner] idler")
    center = _vec(t, "center", "pulley")
    radius = _num(t, "radius", "pulley")
    mass = _num(t, "mass", "pulley")
    inertia = _num(t, "inertia", "pulley")
    driven = t.boolean("driven")
    if not driven:
        for k in _DRIVEN_ONLY:
            if t.has(k):
                t.fail(k, "only a driven pulley (driven = true) takes a prescribed motion")
    speed = _num(t, "speed_rpm", "pulley", required=False)
    accel = _num(t, "acceleration_rpm_per_s", "pulley", required=False)
    amp = _num(t, "fluctuation_amplitude_deg", "pulley", required=False)
    freq = _num(t, "fluctuation_frequency_hz", "pulley", required=False)
    cm = _vec(t, "cm_offset", "pulley", required=False)
    if math.hypot(*cm) >= radius:
        t.fail("cm_offset", f"offset {math.hypot(*cm)!r} m must be smaller than the radius {radius!r} m")
    bd = _num(t, "bearing_damping", "pulley", required=False)
    mu = _num(t, "friction_coefficient", "pulley", required=False)
    target = _num(t, "target_speed_rpm", "pulley", required=False)
    if target is not None:
        if accel == 0.0:
            t.fail("target_speed_rpm", "needs acceleration_rpm_per_s (a run-up) to reach it")
        if (target - abs(speed)) * accel <= 0.0:
            t.fail(
                "target_speed_rpm",
                f"{target!r} rpm cannot be reached from {abs(speed)!r} rpm with acceleration {accel!r} rpm/s",
            )
    if amp > 0.0 and freq == 0.0:
        t.fail("fluctuation_frequency_hz", "missing (required with fluctuation_amplitude_deg > 0)")
    return Pulley(
        name=name,
        center=_arr(center),
        radius=_arr(radius),
        mass=_arr(mass),
        inertia=_arr(inertia),
        driven=driven,
        speed_rpm=_arr(speed),
        acceleration_rpm_per_s=_arr(accel),
        fluctuation_amplitude_deg=_arr(amp),
        fluctuation_frequency_hz=_arr(freq),
        cm_offset=_arr(cm),
        bearing_damping=_arr(bd),
        target_speed_rpm=_arr(target),
        friction_coefficient=_arr(mu),
    )


def _parse_tensioner(data, source) -> Tensioner:
    t = _table(data, "tensioner", source, _TENSIONER_KEYS)
    arm_length = _num(t, "arm_length", "tensioner")
    vals = dict(
        pivot=_arr(_vec(t, "pivot", "tensioner")),
        arm_length=_arr(arm_length),
        pulley_radius=_arr(_num(t, "pulley_radius", "tensioner")),
        arm_mass=_arr(_num(t, "arm_mass", "tensioner")),
        arm_inertia=_arr(_num(t, "arm_inertia", "tensioner")),
        pulley_mass=_arr(_num(t, "pulley_mass", "tensioner")),
        pulley_inertia=_arr(_num(t, "pulley_inertia", "tensioner")),
        spring_stiffness=_arr(_num(t, "spring_stiffness", "tensioner")),
        spring_preload_deg=_arr(_num(t, "spring_preload_deg", "tensioner")),
        arm_angle_deg=_arr(_num(t, "arm_angle_deg", "tensioner", required=False)),
        damping=_arr(_num(t, "damping", "tensioner", required=False)),
    )
    cm = _num(t, "arm_cm_distance", "tensioner", required=False)
    if cm > arm_length:
        t.fail("arm_cm_distance", f"must not exceed arm_length = {arm_length!r}, got {cm!r}")
    vals["arm_cm_distance"] = _arr(cm)
    vals.update(friction_moment=_arr(_num(t, "friction_moment", "tensioner", required=False)),
                friction_asymmetry=_arr(_num(t, "friction_asymmetry", "tensioner", required=False)),
                friction_speed=_arr(_num(t, "friction_speed", "tensioner", required=False)),
                friction_stick_time=_arr(_num(t, "friction_stick_time", "tensioner", required=False)))
    lo = _num(t, "stop_min_deg", "tensioner", required=False)
    hi = _num(t, "stop_max_deg", "tensioner", required=False)
    if lo is not None and hi is not None and lo >= hi:
        t.fail("stop_max_deg", f"must be above stop_min_deg = {lo!r} deg, got {hi!r}")
    # (arm_angle_deg is only the statics' first guess: the installation checks the settled arm)
    if t.has("stop_stiffness") and lo is None and hi is None:
        t.fail("stop_stiffness", "given but there is no stop (stop_min_deg, stop_max_deg): it would change nothing")
    vals.update(stop_min_deg=_arr(lo), stop_max_deg=_arr(hi),
                stop_stiffness=_arr(_num(t, "stop_stiffness", "tensioner", required=False)))
    return Tensioner(**vals)


def _parse_route(data, names, has_tensioner, source) -> Route:
    t = _table(data, "route", source, _ROUTE_KEYS)
    order = t.strings("order")
    if len(order) < 2:
        t.fail("order", f"a belt needs at least two pulleys in its route, got {order!r}")
    known = set(names) | ({TENSIONER} if has_tensioner else set())
    for x in order:
        if x == TENSIONER and not has_tensioner:
            t.fail("order", f"{TENSIONER!r} is in the route but there is no [tensioner] table")
        if x not in known:
            t.fail("order", f"unknown pulley {x!r} (known: {', '.join(sorted(known))})")
    for x in names:
        if x not in order:
            t.fail("order", f"pulley {x!r} is not in the route")
    if has_tensioner and TENSIONER not in order:
        t.fail("order", f"a [tensioner] table is given but {TENSIONER!r} is not in the route")
    back = t.strings("back_side", required=False, default=list(_D("route.back_side")))
    for x in back:
        if x not in order:
            t.fail("back_side", f"{x!r} is not in route.order")
    direction = t.string("direction", required=False, default=_D("route.direction"), choices=DIRECTIONS)
    return Route(order=tuple(order), back_side=tuple(back), direction=direction)


def _parse_model(data, source) -> Model:
    t = _table(data, "model", source, _MODEL_KEYS)
    fidelity = t.string("fidelity", required=False, default=_D("model.fidelity"), choices=FIDELITIES)
    n = t.integer("elements_per_span", required=False, default=_D("model.elements_per_span"), minimum=1, maximum=MAX_ELEMENTS_PER_SPAN)
    effects = t.strings("effects", required=False, default=list(_D("model.effects")))
    for e in effects:
        if e not in EFFECTS:
            t.fail("effects", f"unknown effect {e!r} (known: {', '.join(EFFECTS)})")
    bending = t.string("bending", required=False, default=_D("model.bending"), choices=BENDING_MODELS)
    return Model(fidelity=fidelity, elements_per_span=n, effects=tuple(effects), bending=bending)


def _window(t, group):
    t0 = _num(t, "t_start_s", group, required=False)
    t1 = _num(t, "t_end_s", group, required=False)
    if t1 is not None and t1 <= t0:
        t.fail("t_end_s", f"must be later than t_start_s = {t0!r}, got {t1!r}")
    return _arr(t0), _arr(t1)


def _amplitude_needs_frequency(t, amplitude_key: str, load):
    """``load`` (a parsed [[torque]] or [[span_load]]) when its alternating part
    A sin(2 pi f t + phase) adds something; a non-zero amplitude at f = 0 with sin(phase) = 0 adds
    nothing and is an error, not ignored (f = 0 with a phase is a constant force: a span load's
    steady part)."""
    a, f, phase = (float(x) for x in (getattr(load, amplitude_key), load.frequency_hz, load.phase_deg))
    if a != 0.0 and f == 0.0 and abs(math.sin(math.radians(phase))) < 1e-12:
        t.fail("frequency_hz", f"{amplitude_key} = {a!r} at frequency_hz = 0 and phase_deg = {phase!r} adds "
               "A sin(phase) = 0, nothing: give a frequency > 0 (or a phase, for a constant part)")
    return load


def _parse_torques(data, free_names, source) -> tuple[Torque, ...]:
    if TENSIONER in free_names:
        free_names = [*free_names, ARM]
    if not isinstance(data, list):
        _fail("torque", f"expected an array of tables [[torque]], got {describe(data)}", source)
    out = []
    for i, d in enumerate(data):
        t = _table(d, f"torque[{i}]", source, _TORQUE_KEYS)
        name = t.string("pulley")
        if name not in free_names:
            t.fail(
                "pulley",
                f"{name!r} is not a free pulley of the route (free: {', '.join(free_names) or 'none'}; "
                "a driven pulley's motion is prescribed)",
            )
        t0, t1 = _window(t, "torque")
        load = Torque(
            pulley=name,
            mean_Nm=_arr(_num(t, "mean_Nm", "torque", required=False)),
            amplitude_Nm=_arr(_num(t, "amplitude_Nm", "torque", required=False)),
            frequency_hz=_arr(_num(t, "frequency_hz", "torque", required=False)),
            phase_deg=_arr(_num(t, "phase_deg", "torque", required=False)),
            t_start_s=t0,
            t_end_s=t1,
        )
        out.append(_amplitude_needs_frequency(t, "amplitude_Nm", load))
    return tuple(out)


_DECOUPLER_KEYS = ("pulley", "rotor_inertia", "stiffness", "damping")


def _parse_decouplers(data, free_names, drive_name, source) -> tuple[Decoupler, ...]:
    if not isinstance(data, list):
        _fail("decoupler", f"expected an array of tables [[decoupler]], got {describe(data)}", source)
    out, seen = [], {}
    for i, d in enumerate(data):
        t = _table(d, f"decoupler[{i}]", source, _DECOUPLER_KEYS)
        name = t.string("pulley")
        if name not in free_names or name == TENSIONER:
            t.fail("pulley", f"{name!r} is not a free pulley of the route (free: "
                   f"{', '.join(n for n in free_names if n != TENSIONER) or 'none'}; a driven pulley's motion is "
                   "prescribed)")
        if name == drive_name:
            t.fail("pulley", f"{name!r} is the drive pulley: its rotation carries the belt (a decoupler goes on an "
                   "accessory)")
        if name in seen:
            t.fail("pulley", f"{name!r} already has a decoupler (decoupler[{seen[name]}])")
        seen[name] = i
        out.append(Decoupler(pulley=name, rotor_inertia=_arr(_num(t, "rotor_inertia", "decoupler")),
                             stiffness=_arr(_num(t, "stiffness", "decoupler")),
                             damping=_arr(_num(t, "damping", "decoupler", required=False))))
    return tuple(out)


def _parse_isolator(data, drive, source) -> Isolator:
    t = _table(data, "isolator", source, ("pulley", "stiffness", "damping"))
    name = t.string("pulley")
    if name != drive.name or not drive.driven:
        t.fail("pulley", f"{name!r} is not the driven drive pulley (an isolator joins the driven crank's pulley to its "
               f"hub; here {drive.name!r}{'' if drive.driven else ', not driven'})")
    return Isolator(pulley=name, stiffness=_arr(_num(t, "stiffness", "isolator")),
                    damping=_arr(_num(t, "damping", "isolator", required=False)))


def _parse_span_loads(data, spans, n_elements, fidelity, source) -> tuple[SpanLoad, ...]:
    if not isinstance(data, list):
        _fail("span_load", f"expected an array of tables [[span_load]], got {describe(data)}", source)
    out = []
    for i, d in enumerate(data):
        t = _table(d, f"span_load[{i}]", source, _SPAN_LOAD_KEYS)
        if fidelity != "ancf":
            t.fail("span", "a span load needs the hybrid model (model.fidelity = \"ancf\"): "
                   "the rotational model has no span nodes")
        name = t.string("span")
        if name not in spans:
            t.fail("span", f"unknown span {name!r} (spans: {', '.join(spans)})")
        node = t.integer("node")
        if not 1 <= node <= n_elements - 1:
            t.fail("node", f"must be an interior node, 1 to {n_elements - 1} (elements_per_span - 1), got {node!r}")
        t0, t1 = _window(t, "span_load")
        load = SpanLoad(
            span=name,
            node=node,
            amplitude_N=_arr(_num(t, "amplitude_N", "span_load")),
            frequency_hz=_arr(_num(t, "frequency_hz", "span_load")),
            phase_deg=_arr(_num(t, "phase_deg", "span_load", required=False)),
            t_start_s=t0,
            t_end_s=t1,
        )
        out.append(_amplitude_needs_frequency(t, "amplitude_N", load))
    return tuple(out)


def _parse_initial(data, free_names, has_tensioner, source) -> Initial:
    t = _table(data, "initial", source, _INITIAL_KEYS)
    rot = t.raw("rotation_deg", False) or {}
    if not isinstance(rot, dict):
        t.fail("rotation_deg", f"expected a table of pulley = angle (deg), got {describe(rot)}")
    pairs = []
    for name, v in rot.items():
        if name not in free_names:
            _fail(
                f"initial.rotation_deg.{name}",
                f"not a free pulley of the route (free: {', '.join(free_names) or 'none'})",
                source,
            )
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            _fail(f"initial.rotation_deg.{name}", f"expected a finite number (deg), got {describe(v)}", source)
        msg = schema.problem(schema.FIELDS["initial.rotation_deg"], v)
        if msg:
            _fail(f"initial.rotation_deg.{name}", msg, source)
        pairs.append((name, float(v)))
    arm = _num(t, "arm_angle_deg", "initial", required=False)
    if arm is not None and not has_tensioner:
        t.fail("arm_angle_deg", "there is no [tensioner]")
    return Initial(rotation_deg=tuple(pairs), arm_angle_deg=arm)


def _parse_simulation(data, spans, n_elements, fidelity, source) -> Simulation:
    t = _table(data, "simulation", source, _SIMULATION_KEYS)
    solver = t.string("solver", required=False, default=None, choices=SOLVERS)
    dt = _num(t, "dt_s", "simulation", required=False)
    rho = _num(t, "rho_inf", "simulation", required=False)
    rtol = _num(t, "rtol", "simulation", required=False)
    atol = _num(t, "atol", "simulation", required=False)
    out_dt = _num(t, "output_dt_s", "simulation", required=False)
    nodes = t.strings("nodes", required=False)
    if nodes is not None:
        if fidelity != "ancf" and nodes:
            t.fail("nodes", "node outputs need the hybrid model (model.fidelity = \"ancf\")")
        for x in nodes:
            name, _, k = x.rpartition(":")
            if name not in spans or not k.isdigit() or not 0 <= int(k) <= n_elements:
                t.fail("nodes", f"{x!r} is not \"<span>:<node>\" with a span of {', '.join(spans)} "
                       f"and a node 0 to {n_elements}")
        nodes = tuple(nodes)
    max_steps = t.integer("max_steps", required=False, default=_D("simulation.max_steps"), minimum=1)
    return Simulation(solver=solver, dt_s=dt, rho_inf=rho, rtol=rtol, atol=atol, output_dt_s=out_dt,
                      nodes=nodes, max_steps=max_steps)


def _check_effects(scene: Scene, source: str):
    """A parameter of an effect that is not switched on is an error, not silently ignored (each
    effect module says which parameters it owns: beltjax.drive.effects)."""
    from beltjax.drive.effects import effects_of

    for key, name in effects_of(scene).unlisted_parameters(scene):
        _fail(key, f"given but \"{name}\" is not in model.effects", source)
    from beltjax.drive import belt_slip

    refused = belt_slip.check(scene)
    if refused is not None:
        _fail(*refused, source)


#: the key a listed effect must find in its scene file, (table, key): without it the effect would
#: change nothing (:func:`listed_without_key`; ``belt_slip`` acts with its default slip speed)
LISTED_KEYS = {
    "belt_damping": ("belt", "CA"),
    "bearing_damping": ("pulley", "bearing_damping"),
    "tensioner_damping": ("tensioner", "damping"),
    "unbalance": ("pulley", "cm_offset"),
    "speed_fluctuation": ("pulley", "fluctuation_amplitude_deg"),  # or a [[fluctuation]] table
    "tensioner_friction": ("tensioner", "friction_moment"),
}


def listed_without_key(scene: Scene, doc: dict) -> list[tuple[str, str, str]]:
    """(effect, table, key) of each listed effect whose :data:`LISTED_KEYS` key the scene file's
    dict ``doc`` (as parsed, or as :func:`beltjax.scene.write.scene_document` builds it) gives
    nowhere.  The reader refuses the first (:func:`_check_listed_effects`); the writer adds them."""
    from beltjax.drive.effects import effects_of

    def tables(name):
        v = doc.get(name)
        return [x for x in v if isinstance(x, dict)] if isinstance(v, list) else [v] if isinstance(v, dict) else []

    out = []
    for name in (m.name for m in effects_of(scene).listed):
        if name not in LISTED_KEYS or (name == "speed_fluctuation" and scene.fluctuations):
            continue
        table, key = LISTED_KEYS[name]
        if not any(key in t for t in tables(table)):
            out.append((name, table, key))
    return out


def _check_listed_effects(scene: Scene, data: dict, source: str) -> None:
    """A listed effect whose parameter the file does not give anywhere would change nothing: an
    error, as a parameter given while its effect is off (:func:`_check_effects`).  An explicit
    zero passes (a nominal a sweep can vary)."""
    for name, table, key in listed_without_key(scene, data)[:1]:
        what = "[[fluctuation]] table or " if name == "speed_fluctuation" else ""
        given = f"{table}[i].{key}" if table == "pulley" else f"{table}.{key}"
        _fail("model.effects", f"\"{name}\" is listed but the scene gives no {what}{given}: it would change "
              "nothing (give it, or leave the effect out)", source)


def _check_run_settings(scene: Scene, source: str) -> None:
    """A [simulation] key the scene's solver does not read is an error, not silently ignored:
    rtol and atol with the fixed-step generalized_alpha, rho_inf with an adaptive solver."""
    from beltjax.drive.spans import spans_of

    sim, bare = scene.simulation, Simulation()
    solver = sim.solver or spans_of(scene).default_solver
    if solver == "generalized_alpha":
        for k in ("rtol", "atol"):
            if getattr(sim, k) != getattr(bare, k):
                _fail(f"simulation.{k}", "given but the solver generalized_alpha takes fixed steps of dt_s (its "
                      "tolerance is its Newton iteration's): leave it out, or give an adaptive solver "
                      "(tsit5, dopri8, kvaerno5)", source)
    elif sim.rho_inf != bare.rho_inf:
        _fail("simulation.rho_inf", f"given but the solver {solver} is adaptive: rho_inf sets generalized_alpha's "
              "numerical damping; leave it out, or give solver = \"generalized_alpha\"", source)

