"""Accepted ranges and the same checks on every path (issue 20, items 2 and 4).

One table of out-of-range magnitudes (the issue's examples and more of the same class) goes
through the scene file (the command line: exit 2, one line naming the key, the value and
the range with its unit), through ``parameters.set_value`` (the same message after the
path) and through a sweep case (status ``invalid_value``, NaN outputs, no crash).  The
derived float64 limits, overlapping pulleys, the drive-pulley speed rule and the Python
API's entry checks are checked the same way.  Nothing here compiles except one sweep batch
(statics of the two-pulley bench, 2 elements per span).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import pathlib
import sys
import tomllib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import (BeltjaxError, analyse_campbell, analyse_modes, analyse_span, analyse_statics, optimize,
                     parameters, schema, scene as scene_mod, sweep, validate)
from beltjax.cli import main
from beltjax.scene import SceneError, loads_scene, parse_scene

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _scenes import SCENES, scene_text, substitute  # noqa: E402

T200 = scene_text("two_pulley_T200.toml")
BENCH = scene_text("tensioner_bench_stage2.toml")
PREFIX = "beltjax: error: "
SPAN = dict(length=0.67, tension=100.0, EA=111190.0, EI=0.034, rhoA=0.121)


@dataclasses.dataclass(frozen=True)
class Row:
    id: str
    base: str  # "T200" or "BENCH"
    path: str  # parameter path
    key: str  # scene-file key
    value: float
    edit: tuple[str, str]  # the scene-file text change


def row(id, base, path, key, value, old, new):
    return Row(id, base, path, key, value, (old, new))


A, C = "pulley.alternator", "pulley[1]"
ROWS = [
    row("EI-1e20", "T200", "belt.EI", "belt.EI", 1e20, "EI = 0.034", "EI = 1e20"),
    row("EI-1e300", "T200", "belt.EI", "belt.EI", 1e300, "EI = 0.034", "EI = 1e300"),
    row("EA-1e20", "T200", "belt.EA", "belt.EA", 1e20, "EA = 111190.0", "EA = 1e20"),
    row("EA-1e-300", "T200", "belt.EA", "belt.EA", 1e-300, "EA = 111190.0", "EA = 1e-300"),
    row("rhoA-1e-300", "T200", "belt.rhoA", "belt.rhoA", 1e-300, "rhoA = 0.12101", "rhoA = 1e-300"),
    row("rhoA-1e300", "T200", "belt.rhoA", "belt.rhoA", 1e300, "rhoA = 0.12101", "rhoA = 1e300"),
    row("CA-1e300", "T200", "belt.CA", "belt.CA", 1e300, "rhoA = 0.12101", "rhoA = 0.12101\nCA = 1e300"),
    row("tension-1e300", "T200", "belt.static_tension", "belt.static_tension", 1e300,
        "static_tension = 200.0", "static_tension = 1e300"),
    row("tension-1e-300", "T200", "belt.static_tension", "belt.static_tension", 1e-300,
        "static_tension = 200.0", "static_tension = 1e-300"),
    row("radius-1e-300", "T200", f"{A}.radius", f"{C}.radius", 1e-300, "radius = 0.0375", "radius = 1e-300"),
    row("radius-1e300", "T200", f"{A}.radius", f"{C}.radius", 1e300, "radius = 0.0375", "radius = 1e300"),
    row("centre-1e200", "T200", f"{A}.center.x", f"{C}.center", 1e200,
        "center = [0.2232, 0.135]", "center = [1e200, 0.135]"),
    row("centre-y-minus-1e200", "T200", f"{A}.center.y", f"{C}.center", -1e200,
        "center = [0.2232, 0.135]", "center = [0.2232, -1e200]"),
    row("mass-1e300", "T200", f"{A}.mass", f"{C}.mass", 1e300, "mass = 2.1543", "mass = 1e300"),
    row("inertia-1e-300", "T200", f"{A}.inertia", f"{C}.inertia", 1e-300, "inertia = 1.7019e-3", "inertia = 1e-300"),
    row("inertia-1e300", "T200", f"{A}.inertia", f"{C}.inertia", 1e300, "inertia = 1.7019e-3", "inertia = 1e300"),
    row("speed-1e300", "T200", "pulley.crank.speed_rpm", "pulley[0].speed_rpm", 1e300,
        "speed_rpm = 0.0", "speed_rpm = 1e300"),
    row("bearing-damping-1e300", "T200", f"{A}.bearing_damping", f"{C}.bearing_damping", 1e300,
        "inertia = 1.7019e-3", "inertia = 1.7019e-3\nbearing_damping = 1e300"),
    row("cm-offset-1e300", "T200", f"{A}.cm_offset.x", f"{C}.cm_offset", 1e300,
        "inertia = 1.7019e-3", "inertia = 1.7019e-3\ncm_offset = [1e300, 0.0]"),
    row("arm-length-1e300", "BENCH", "tensioner.arm_length", "tensioner.arm_length", 1e300,
        "arm_length = 0.094", "arm_length = 1e300"),
    row("pivot-1e200", "BENCH", "tensioner.pivot.x", "tensioner.pivot", 1e200,
        "pivot = [0.64335, 0.0884]", "pivot = [1e200, 0.0884]"),
    row("spring-1e-300", "BENCH", "tensioner.spring_stiffness", "tensioner.spring_stiffness", 1e-300,
        "spring_stiffness = 21.14", "spring_stiffness = 1e-300"),
    row("preload-1e300", "BENCH", "tensioner.spring_preload_deg", "tensioner.spring_preload_deg", 1e300,
        "spring_preload_deg = 94.5", "spring_preload_deg = 1e300"),
    row("arm-inertia-1e300", "BENCH", "tensioner.arm_inertia", "tensioner.arm_inertia", 1e300,
        "arm_inertia = 0.9969e-3", "arm_inertia = 1e300"),
    row("idler-radius-1e-300", "BENCH", "tensioner.pulley_radius", "tensioner.pulley_radius", 1e-300,
        "pulley_radius = 0.037", "pulley_radius = 1e-300"),
]
TEXT = {"T200": T200, "BENCH": BENCH}


def _expected(r: Row) -> str:
    """The message after the key: ``must lie in [low, high] unit (why), got value``."""
    msg = schema.problem(schema.field(r.path), r.value)
    assert msg is not None and msg.startswith("must lie in [") and f"got {r.value!r}" in msg
    unit = schema.field(r.path).unit
    assert f"] {unit} (" in msg  # the range with its unit and its reason
    return msg


@pytest.fixture(scope="module")
def scenes():
    return {k: loads_scene(v) for k, v in TEXT.items()}


@pytest.mark.parametrize("r", ROWS, ids=[r.id for r in ROWS])
def test_scene_file_names_the_key_and_the_range(r, tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(substitute(TEXT[r.base], r.edit))
    code = main(["statics", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert err == f"{PREFIX}{path}: {r.key}: {_expected(r)}\n"  # the command line names the file first
    assert not [p for p in (tmp_path / "out").rglob("*") if p.is_file()] if (tmp_path / "out").exists() else True


@pytest.mark.parametrize("r", ROWS, ids=[r.id for r in ROWS])
def test_set_value_gives_the_same_message(r, scenes):
    with pytest.raises(parameters.ParameterError) as e:
        parameters.set_value(scenes[r.base], r.path, r.value)
    assert str(e.value) == f"{r.path}: {_expected(r)}"


def test_set_value_under_jit_is_not_checked(scenes):
    """Traced values are never checked (no Python branching on them)."""
    f = jax.jit(lambda v: parameters.set_value(scenes["T200"], "belt.EI", v).belt.EI)
    assert float(f(1e20)) == 1e20
    g = jax.grad(lambda v: parameters.set_value(scenes["T200"], "belt.EI", v).belt.EI * 2.0)
    assert float(g(-1.0)) == 2.0


# --------------------------------------------------------------------------- sweep cases


def _small(sc, n=2):
    return eqx.tree_at(lambda s: s.model, sc, dataclasses.replace(sc.model, elements_per_span=n))


def _case_table(sc, changes: list[dict]):
    """{path: (n,) values}: case 0 the scene as it is, case i + 1 with changes[i]."""
    paths = sorted({p for c in changes for p in c})
    nominal = {p: sweep.nominal_value(sc, p) for p in paths}
    return {p: np.array([nominal[p]] + [c.get(p, nominal[p]) for c in changes]) for p in paths}


@pytest.fixture(scope="module")
def swept(scenes):
    """Every out-of-range row of the two-pulley bench as a sweep case, with overlapping
    pulleys, derived float64 limits, and values a scene file accepts (EI = 0, massless
    pulleys), in one batch (2 elements per span).  The effects that own a swept parameter are
    listed, so that each parameter acts (a sweep of an unlisted effect's parameter is refused as a
    whole)."""
    rows = [r for r in ROWS if r.base == "T200"]
    sc = _small(scenes["T200"])
    owners = sorted({schema.field(r.path).effect for r in rows} - {"", *sc.model.effects})
    sc = eqx.tree_at(lambda s: s.model, sc, dataclasses.replace(sc.model, effects=(*sc.model.effects, *owners)))
    changes = [{r.path: r.value} for r in rows]
    extra = {
        "overlap": {f"{A}.center.x": 0.80, f"{A}.center.y": 0.2},
        "ill_conditioned": {"belt.EA": 1e10, "belt.EI": 0.0, "belt.static_tension": 1e-3},
        "far_from_origin": {f"{A}.center.x": 0.2232 + 9e4, "pulley.crank.center.x": 0.8973 + 9e4,
                            f"{A}.radius": 1e-4},
        "accepted": {"belt.EI": 0.0, f"{A}.mass": 0.0, "pulley.crank.mass": 0.0},
    }
    values = _case_table(sc, changes + list(extra.values()))
    res = sweep.evaluate(sc, values, ("statics",), 4, chunk=4)
    return rows, list(extra), res


def test_sweep_cases_out_of_range_are_invalid_with_nan_outputs(swept):
    rows, extra, res = swept
    status = list(res["status"])
    assert status[0] == "ok"
    for i, r in enumerate(rows, start=1):
        assert status[i] == "invalid_value", (r.id, status[i])
        assert np.all(np.isnan(res["span_tensions_N"][i])) and np.all(np.isnan(res["hub_forces_N"][i])), r.id
        assert np.isnan(res["installation_tension_N"][i]) and not res["converged"][i]
    assert np.all(np.isfinite(res["span_tensions_N"][0])) and res["converged"][0]


def test_sweep_cases_overlap_and_float64_limits_get_their_status(swept):
    rows, extra, res = swept
    status = dict(zip(extra, res["status"][1 + len(rows):]))
    assert status == {"overlap": "overlap", "ill_conditioned": "ill_conditioned",
                      "far_from_origin": "ill_conditioned", "accepted": "ok"}
    i = 1 + len(rows) + extra.index("overlap")
    assert np.all(np.isnan(res["hub_forces_N"][i]))
    j = 1 + len(rows) + extra.index("accepted")
    assert np.all(np.isfinite(res["span_tensions_N"][j]))
    assert sweep.failures(res)["overlap"]["reason"] == sweep.REASONS["overlap"]


def test_sweep_of_the_tensioner_bench_checks_each_case(scenes):
    """The tensioner rows as sweep cases: the statuses the sweep gives before computing
    (the batch itself is exercised on the two-pulley bench above; the tensioner's statics
    compiles for 30-45 s)."""
    sc = scenes["BENCH"]
    rows = [r for r in ROWS if r.base == "BENCH"]
    changes = [{r.path: r.value} for r in rows] + [{"tensioner.pivot.x": 0.80, "tensioner.pivot.y": 0.15}]
    values = _case_table(sc, changes)
    codes = sweep._precheck(sc, values, len(changes) + 1)
    assert [sweep.STATUS[c] for c in codes] == ["ok"] + ["invalid_value"] * len(rows) + ["overlap"]


def test_case_status_messages_match_the_scene_file(scenes):
    """The vectorised checks of a sweep and the scene file's checks say the same."""
    sc = scenes["T200"]
    values = {f"{A}.center.x": np.array([0.2232, 0.80]), "belt.EI": np.array([1e20, 0.034])}
    status, first = validate.case_status(sc, values, 2)
    assert list(status) == ["invalid_value", "overlap"]
    with pytest.raises(SceneError) as e:
        loads_scene(substitute(T200, ("center = [0.2232, 0.135]", "center = [0.80, 0.135]")))
    assert first["overlap"] == (1, str(e.value))


# --------------------------------------------------------------------------- derived limits

THREE = substitute(
    T200, ('order = ["crank", "alternator"]', 'order = ["crank", "idler", "alternator"]'),
    ("back_side = []", 'back_side = ["idler"]'),
    ("[route]", '[[pulley]]\nname = "idler"\ncenter = [IDLER]\nradius = 0.03\nmass = 0.3\ninertia = 0.2e-3\n\n[route]'))


def _idler(gap):
    """The idler on the crank's belt side with a crossed span of ``gap`` m to the crank."""
    c = np.array([0.8973, 0.2])
    u = np.array([0.78309, 0.13406]) - c
    p = c + math.hypot(gap, 0.1315) * u / np.linalg.norm(u)
    return f"{float(p[0])!r}, {float(p[1])!r}"


DERIVED = [
    ("pinched-span", THREE.replace("IDLER", _idler(1e-4)), "pulley[2].center",
     "span crank-idler is 0.0001 m long beside span alternator-crank"),
    ("EA-over-tension", substitute(T200, ("EA = 111190.0", "EA = 1e10"), ("EI = 0.034", "EI = 0.0"),
                                   ("static_tension = 200.0", "static_tension = 1e-3")),
     "belt.EA", "the axial stiffness (1e+10 N over 16 elements per span) is"),
    ("EI-over-EA", substitute(T200, ("EA = 111190.0", "EA = 1.0"), ("EI = 0.034", "EI = 1e5")),
     "belt.EI", "EI / (EA Le^2) ="),
    ("far-from-origin", substitute(T200, ("center = [0.8973, 0.2]", "center = [90000.8973, 0.2]"),
                                   ("center = [0.2232, 0.135]", "center = [90000.2232, 0.135]"),
                                   ("radius = 0.0375", "radius = 1e-4")),
     "pulley[0].center", "m from the origin"),
]


@pytest.mark.parametrize("text,key,expect", [d[1:] for d in DERIVED], ids=[d[0] for d in DERIVED])
def test_derived_float64_limits_name_the_cause(text, key, expect):
    with pytest.raises(SceneError) as e:
        loads_scene(text)
    msg = str(e.value)
    assert msg.startswith(f"{key}: ") and expect in msg and "\n" not in msg, msg
    assert "float64" in msg


def test_the_hard_tests_short_span_is_accepted():
    """The robustness suite's 1 cm span beside 0.56 and 0.67 m ones (and a 1 mm one) load."""
    for gap in (1e-2, 1e-3):
        sc = loads_scene(THREE.replace("IDLER", _idler(gap)))
        assert min(np.asarray(sc.geometry().span_length)) == pytest.approx(gap, rel=1e-6)


def test_set_value_checks_the_layout_and_the_derived_limits(scenes):
    sc = scenes["T200"]
    with pytest.raises(parameters.ParameterError, match=r"^pulley\.alternator\.center\.x: pulleys 'crank' and "
                                                        r"'alternator' overlap"):
        parameters.set_value(sc, f"{A}.center.x", 0.8)
    with pytest.raises(parameters.ParameterError, match=r"^belt\.EA: the axial stiffness"):
        parameters.set_values(sc, {"belt.EA": 1e10, "belt.EI": 0.0, "belt.static_tension": 1e-3})
    ok = parameters.set_values(sc, {"belt.EI": 0.0, f"{A}.mass": 0.0})  # what a scene file accepts
    assert float(ok.belt.EI) == 0.0


# --------------------------------------------------------------------------- the drive pulley's speed


@pytest.mark.parametrize("path,expect", [
    (f"{A}.speed_rpm", "only the drive pulley takes a speed: a driven pulley (driven = true), else the first pulley "
                       "(here 'crank')"),
    (f"{A}.acceleration_rpm_per_s", "only a driven pulley (driven = true) takes a prescribed motion"),
    (f"{A}.fluctuation_amplitude_deg", "only a driven pulley (driven = true) takes a prescribed motion"),
])
def test_only_the_drive_pulley_takes_a_speed(scenes, path, expect):
    sc = scenes["T200"]
    assert path not in parameters.paths(sc)
    with pytest.raises(parameters.ParameterError) as e:
        parameters.set_value(sc, path, 100.0)
    assert str(e.value) == f"{path}: {expect}"
    spec = sweep.parse_spec({"grid": [{"parameter": path, "values": [0.0, 100.0]}]})
    with pytest.raises(sweep.SweepError) as e:
        sweep.cases(sc, spec)
    assert str(e.value) == f"grid[0].parameter: {path}: {expect}"


def test_sweep_grid_values_no_case_could_use_and_values_a_scene_accepts(scenes):
    sc = scenes["T200"]
    bad = sweep.parse_spec({"grid": [{"parameter": "belt.EI", "values": [0.034, 1e20]}]})
    with pytest.raises(sweep.SweepError) as e:
        sweep.cases(sc, bad)
    assert str(e.value) == f"grid[0].values: belt.EI {schema.problem(schema.FIELDS['belt.EI'], 1e20)}"
    good = sweep.parse_spec({"grid": [{"parameter": "belt.EI", "values": [0.0, 0.034]},
                                      {"parameter": f"{A}.mass", "values": [0.0]}]})
    assert sweep.cases(sc, good)["belt.EI"].tolist() == [0.0, 0.034]


def test_optimize_bounds_outside_the_range(scenes):
    spec = {"variable": [{"parameter": "tensioner.pivot.x", "lower": -1e200, "upper": 0.7}],
            "objective": [{"kind": "hub_load", "pulley": "alternator"}]}
    with pytest.raises(optimize.OptimizeError) as e:
        optimize.parse(copy.deepcopy(spec), scenes["BENCH"])
    assert str(e.value) == ("variable[0].lower: tensioner.pivot.x "
                            f"{schema.problem(schema.FIELDS['tensioner.pivot'], -1e200)}")


# --------------------------------------------------------------------------- the Python API


@pytest.mark.parametrize("arg,value", [("length", math.nan), ("speed", math.nan), ("length", 1e-300),
                                       ("tension", math.inf), ("EI", 1e20), ("rhoA", 1e300)])
def test_analyse_span_raises_the_command_lines_message(arg, value, tmp_path, capsys):
    with pytest.raises(BeltjaxError) as e:
        analyse_span(**{**SPAN, arg: value})
    api = str(e.value)
    assert api.startswith(f"{arg}: ") and "\n" not in api
    argv = ["span"] + [x for k, v in {**SPAN, arg: value}.items() for x in (f"--{k}", repr(v))]
    assert main([*argv, "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"{PREFIX}--{api}\n"  # the same message; the key is the option's name


def test_analyse_statics_and_modes_check_the_scene_and_the_speed(scenes, tmp_path, capsys):
    sc = scenes["T200"]
    for f in (analyse_statics, analyse_modes):
        for v, expect in ((math.nan, "speed: must be finite, got nan"), (-1.0, "speed: must be >= 0, got -1.0")):
            with pytest.raises(BeltjaxError) as e:
                f(sc, v)
            assert str(e.value) == expect
    overlapping = eqx.tree_at(lambda s: s.pulleys[1].center, sc, jnp.array([0.80, 0.135]))
    path = tmp_path / "scene.toml"
    path.write_text(substitute(T200, ("center = [0.2232, 0.135]", "center = [0.80, 0.135]")))
    assert main(["modal", str(path), "--out", str(tmp_path / "out")]) == 2
    cli = capsys.readouterr().err
    for f in (analyse_statics, analyse_modes):
        with pytest.raises(BeltjaxError) as e:
            f(overlapping)
        assert cli == f"{PREFIX}{path}: {e.value}\n"


@pytest.mark.parametrize("rpm,expect", [([0.0, math.nan, 100.0], "rpm[1]: must be finite, got nan"),
                                        ([-5.0, 100.0], "rpm[0]: must be >= 0, got -5.0"),
                                        ([0.0, math.inf], "rpm[1]: must be finite, got inf"),
                                        ([], "rpm: expected at least one speed")])
def test_analyse_campbell_rejects_bad_speeds(scenes, rpm, expect):
    with pytest.raises(BeltjaxError) as e:
        analyse_campbell(scenes["T200"], rpm)
    assert str(e.value) == expect


# --------------------------------------------------------------------------- one schema


def test_every_parameter_path_and_scene_key_has_a_schema_entry(scenes):
    for sc in scenes.values():
        for p in parameters.paths(sc):
            assert schema.field(p) is not None, p
    numeric = {"belt": scene_mod._BELT_KEYS, "pulley": set(scene_mod._PULLEY_KEYS) - {"name", "driven"},
               "tensioner": scene_mod._TENSIONER_KEYS, "torque": set(scene_mod._TORQUE_KEYS) - {"pulley"},
               "span_load": set(scene_mod._SPAN_LOAD_KEYS) - {"span", "node"},
               "simulation": set(scene_mod._SIMULATION_KEYS) - {"solver", "nodes", "max_steps"},
               "initial": scene_mod._INITIAL_KEYS}
    for group, keys in numeric.items():
        for k in keys:
            assert f"{group}.{k}" in schema.FIELDS, f"{group}.{k}"
    for key, f in schema.FIELDS.items():
        assert f.low < f.high and f.why, key
    doc = scene_mod.__doc__
    assert all(k in doc for k in schema.FIELDS if k.split(".")[0] in ("belt", "pulley", "tensioner"))


def _file_edit(data: dict, sc, path: str, value):
    """The parsed-TOML dict with the scene-file key of parameter ``path`` set to ``value``."""
    parts = path.split(".")
    if parts[0] == "belt":
        table, rest = data["belt"], parts[1:]
        if rest[0] in ("length", "static_tension"):
            table.pop("static_tension" if rest[0] == "length" else "length", None)
    elif parts[0] == "pulley":
        table = data["pulley"][[p.name for p in sc.pulleys].index(parts[1])]
        rest = parts[2:]
    else:
        table, rest = data["tensioner"], parts[1:]
    if len(rest) == 2:
        vec = list(table.get(rest[0], [0.0, 0.0]))
        vec["xy".index(rest[1])] = value
        table[rest[0]] = vec
    else:
        table[rest[0]] = value


@pytest.mark.parametrize("base", ["T200", "BENCH"])
def test_the_scene_file_and_set_value_enforce_the_same_ranges(scenes, base):
    """Every parameter path, set just above its range's upper bound and just below its lower
    bound, is refused by the scene file and by set_value with the same message after the key."""
    sc = scenes[base]
    raw = tomllib.loads(TEXT[base])
    checked = 0
    for p in parameters.paths(sc):
        f = schema.field(p)
        for value in (f.high * 10.0, f.low - max(1.0, abs(f.low))):
            data = copy.deepcopy(raw)
            _file_edit(data, sc, p, value)
            with pytest.raises(SceneError) as file_err:
                parse_scene(data)
            with pytest.raises(parameters.ParameterError) as set_err:
                parameters.set_value(sc, p, value)
            tail = schema.problem(f, value)
            assert str(file_err.value).endswith(f": {tail}") and str(set_err.value) == f"{p}: {tail}", p
            checked += 1
    assert checked == 2 * len(parameters.paths(sc))


def test_every_shipped_scene_loads():
    files = sorted(p for p in SCENES.rglob("*.toml") if "[belt]" in p.read_text())
    assert len(files) >= 13
    for p in files:
        sc = scene_mod.load_scene(p)
        assert validate.scene_problem(sc) is None, p



def test_the_idler_is_checked_where_the_arm_settles():
    """The scene's arm_angle_deg is only Newton's starting guess: the layout checks run again with
    the idler at the solved arm angle (statics, and every sweep case at its own angle).  With the
    crank moved to x = 0.84 m the guess (60 deg) is clear and the idler overlaps the crank's rim
    between about 20 and 40 deg."""
    from beltjax import statics

    sc = loads_scene(substitute(BENCH, ("center = [0.8973, 0.2]", "center = [0.84, 0.2]"),
                                ("arm_angle_deg = 46.5", "arm_angle_deg = 60.0")))
    statics.check_solved(sc, 450.0, 60.0)
    with pytest.raises(BeltjaxError, match=r"^tensioner: at its equilibrium arm angle 30 deg: no crossed tangent "
                                           r"from 'crank' to 'tensioner': centre distance 0\.13"):
        statics.check_solved(sc, 450.0, 30.0)
    status, first = validate.solved_status(sc, 450.0, np.array([60.0, 30.0, 90.0, 25.0]), n=4)
    assert status.tolist() == ["ok", "overlap", "ok", "overlap"]
    assert first["overlap"][0] == 1


def test_a_belt_given_by_length_is_checked_at_its_installed_tension(scenes):
    """The string-spread limit needs the tension, which a belt given by its length has only once
    installed: the statics checks it there (EA = 1e10 N installed at about 1 mN, 2 elements)."""
    from beltjax import statics

    sc = _small(scenes["T200"])
    inst = statics.install(sc)
    path = float(inst.belt_length * inst.stretch)
    text = substitute(T200, ("EA = 111190.0", "EA = 1e10"), ("EI = 0.034", "EI = 0.0"),
                      ("static_tension = 200.0", f"length = {path / (1 + 1e-13)!r}"))
    bad = _small(loads_scene(text))  # accepted: no tension before the statics
    with pytest.raises(BeltjaxError, match=r"^belt\.EA: the axial stiffness \(1e\+10 N over 2 elements per span\) "
                                           r"is .* times the string stiffness .* at tension 0\.00"):
        analyse_statics(bad)
    status, _ = validate.solved_status(bad, np.array([1e-3, 1e3]), n=2)
    assert status.tolist() == ["ill_conditioned", "ok"]


def test_a_sweep_checks_each_case_at_its_solved_installation(monkeypatch):
    """sweep.evaluate hands each case's solved arm angle and installed tension to the checks, and
    a case that fails them gets their status and NaN outputs (rotational model, statics only)."""
    sc = loads_scene(substitute(BENCH, ('fidelity = "ancf"', 'fidelity = "rotational"')))
    seen = {}
    real = validate.solved_status

    def spy(scene, tension_N, arm_angle_deg=None, values=None, n=1):
        seen["T"], seen["angles"] = np.array(tension_N, dtype=float), np.array(arm_angle_deg, dtype=float)
        status, first = real(scene, tension_N, arm_angle_deg, values, n)
        assert status.tolist() == ["ok", "ok"]
        status[1] = "overlap"  # as if the second case's idler met a pulley where its arm settled
        return status, first

    monkeypatch.setattr(validate, "solved_status", spy)
    res = sweep.evaluate(sc, {"tensioner.spring_preload_deg": np.array([94.5, 90.0])}, ("statics",), chunk=2)
    assert res["status"].tolist() == ["ok", "overlap"]
    assert seen["angles"][0] == res["tensioner_angle_deg"][0] and seen["T"][0] == res["installation_tension_N"][0]
    assert 40.0 < seen["angles"][0] < 70.0 and 40.0 < seen["angles"][1] < 70.0
    assert 300.0 < seen["T"][1] < 700.0
    assert np.all(np.isnan(res["span_tensions_N"][1])) and np.all(np.isfinite(res["span_tensions_N"][0]))
