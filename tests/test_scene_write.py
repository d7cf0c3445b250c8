"""Writing scenes (beltjax.scene.write, beltjax.tomlwrite): every shipped scene, a changed scene,
a measured trace, hostile strings and the optimiser's scene file read back to the same scene."""

from __future__ import annotations

import dataclasses
import math
import pathlib
import tomllib

import numpy as np
import pytest

from beltjax import parameters, tomlwrite
from beltjax.optimize import OptimizeError, optimised_scene_text
from beltjax.scene import SceneError, dumps_scene, load_scene, loads_scene, write_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "scenes").glob("*.toml")) + sorted((ROOT / "identification" / "examples").rglob("*.toml"))
SCENES = [p for p in SCENES if "[belt]" in p.read_text()]


def _same(a, b):
    """Every parameter path and the structure alike, numbers bit for bit."""
    assert parameters.paths(a) == parameters.paths(b)
    for p in parameters.paths(a):
        x, y = np.asarray(parameters.get_value(a, p)), np.asarray(parameters.get_value(b, p))
        assert np.array_equal(x, y, equal_nan=True), (p, x, y)
    for attr in ("route", "model", "initial", "simulation", "description"):
        assert getattr(a, attr) == getattr(b, attr), attr
    assert [p.name for p in a.pulleys] == [p.name for p in b.pulleys]
    assert [p.driven for p in a.pulleys] == [p.driven for p in b.pulleys]
    assert (a.tensioner is None) == (b.tensioner is None) and (a.isolator is None) == (b.isolator is None)
    for x, y in ((a.belt.length, b.belt.length), (a.belt.static_tension, b.belt.static_tension)):
        assert (x is None) == (y is None)
    for name in ("torques", "fluctuations", "decouplers", "span_loads"):
        assert len(getattr(a, name)) == len(getattr(b, name)), name


@pytest.mark.parametrize("path", SCENES, ids=[p.name for p in SCENES])
def test_every_shipped_scene_reads_back(path, tmp_path):
    scene = load_scene(path)
    write_scene(scene, tmp_path / "copy.toml", header="a copy")
    text = (tmp_path / "copy.toml").read_text()
    assert text.startswith("# a copy\n")
    _same(scene, load_scene(tmp_path / "copy.toml"))


def test_changed_numbers_read_back_to_the_bit():
    """Numbers set in code (no short decimal form) come back bit for bit."""
    scene = load_scene(ROOT / "scenes" / "fead_8pulley_friction.toml")
    rng = np.random.default_rng(3)
    values = {p: float(parameters.get_value(scene, p)) * (1 + 1e-3 * rng.standard_normal())
              for p in ("belt.EA", "belt.EI", "pulley.ac.center.x", "tensioner.spring_stiffness",
                        "tensioner.friction_moment", "pulley.alternator.inertia")}
    changed = parameters.set_values(scene, values)
    back = loads_scene(dumps_scene(changed))
    _same(changed, back)
    for p, v in values.items():
        assert float(parameters.get_value(back, p)) == v


def test_a_measured_trace_is_written_as_its_harmonics(tmp_path):
    fead = (ROOT / "scenes" / "fead_8pulley.toml").read_text()
    head, _, _ = fead.partition("[[fluctuation]]")
    alpha = np.linspace(0.0, 720.0, 721)
    rpm = 800.0 * (1.0 + 2 * math.radians(0.6) * np.cos(2 * np.radians(alpha)))
    (tmp_path / "crank.csv").write_text("angle_deg,speed_rpm\n" + "".join(f"{float(a)!r},{float(r)!r}\n" for a, r in zip(alpha, rpm)))
    (tmp_path / "scene.toml").write_text(head + '[[fluctuation]]\npulley = "crank"\nfile = "crank.csv"\n')
    scene = load_scene(tmp_path / "scene.toml")
    text = dumps_scene(scene)
    assert "file" not in tomllib.loads(text)["fluctuation"][0] and "read from crank.csv" in text
    back = loads_scene(text)
    assert len(back.fluctuations) == len(scene.fluctuations) == 24
    _same(scene, back)


def test_hostile_strings_and_values_read_back():
    """Quotes, backslashes, TOML syntax and non-ASCII in names, control characters in the
    description (a name must be printable); a name that is not a bare key in [initial] rotation_deg."""
    text = (ROOT / "scenes" / "sim_two_pulley_release.toml").read_text()
    scene = load_scene(ROOT / "scenes" / "sim_two_pulley_release.toml")
    odd = 'alt "x" \\ ] = #ü 漢'
    free = "alternator"  # a free pulley, turned by [initial] rotation_deg
    text = text.replace(f'"{free}"', tomlwrite.string(odd)).replace(f"{{ {free} =", f"{{ {tomlwrite.string(odd)} =")
    text = 'description = ' + tomlwrite.string('line\nnext "q" \\ \x7f [belt]') + "\n" + text.partition("\n")[2]
    scene = loads_scene(text)
    assert scene.pulleys[[p.name for p in scene.pulleys].index(odd)].name == odd
    assert dict(scene.initial.rotation_deg)[odd] == 2.0 and scene.description.startswith("line\nnext")
    _same(scene, loads_scene(dumps_scene(scene)))


def test_the_toml_values():
    doc = {"a": 1, "b": -0.0, "c": 1e-310, "d": [1.5, 2, "x"], "e": True, "f": "é\"\\\n",
           "t": {"k": 0.1 + 0.2, "inline": {"a b": 1, "c": [1e300]}}, "arr": [{"x": 1}, {"x": 2.5}]}
    back = tomllib.loads(tomlwrite.dumps(doc))
    assert back == doc and math.copysign(1, back["b"]) < 0
    specials = tomllib.loads(tomlwrite.dumps({"x": [math.inf, -math.inf, math.nan]}))["x"]
    assert specials[:2] == [math.inf, -math.inf] and math.isnan(specials[2])
    with pytest.raises(TypeError):
        tomlwrite.value(object())


def test_a_scene_no_file_may_hold_is_refused():
    """A value no scene file may hold (a belt damping without its effect listed) is refused with
    its key, not written as a file that means something else."""
    scene = load_scene(ROOT / "scenes" / "two_pulley_T200.toml")
    bad = dataclasses.replace(scene, belt=dataclasses.replace(scene.belt, CA=np.float64(3.0)))
    with pytest.raises(SceneError, match=r"belt\.CA") as err:
        dumps_scene(bad)
    assert "\n" not in str(err.value)


def test_optimised_scene_file_in_place_or_whole(tmp_path):
    """The optimiser edits the file's text where it can (comments kept); a layout its editor does
    not know (a multi-line array) or a scene not read from a file is written whole, with a note;
    either way the file reads back to the optimised scene."""
    path = ROOT / "scenes" / "two_pulley_T200.toml"
    scene = load_scene(path)
    values = {"pulley.alternator.center.x": 0.2301, "belt.EI": 0.031}
    expected = parameters.set_values(scene, values)
    text, note = optimised_scene_text(scene, values, "# head\n", path)
    assert note is None and "[optimised; was" in text
    _same(expected, loads_scene(text))
    multi = path.read_text().replace("center = [0.2232, 0.135]", "center = [\n  0.2232,\n  0.135,\n]")
    assert multi != path.read_text()
    (tmp_path / "multi.toml").write_text(multi)
    text, note = optimised_scene_text(load_scene(tmp_path / "multi.toml"), values, "# head\n", tmp_path / "multi.toml")
    assert note.startswith("optimized_scene.toml written whole") and text.startswith("# head\n")
    _same(expected, loads_scene(text))
    text, note = optimised_scene_text(scene, values, "# head\n", None)
    assert "not read from a file" in note
    _same(expected, loads_scene(text))
    with pytest.raises(OptimizeError, match="cannot be written"):
        optimised_scene_text(scene, {"belt.CA": 2.0}, "", None)


def test_a_listed_effect_at_zero_is_written_back():
    """A listed effect whose parameter is 0 (a nominal a sweep can vary) keeps its key in the
    written file: the reader refuses a listed effect the file gives no parameter for."""
    from beltjax.scene import dumps_scene, loads_scene
    from beltjax.scene.write import first_difference

    text = (pathlib.Path(__file__).resolve().parents[1] / "scenes" / "fead_8pulley.toml").read_text()
    for old, new in (("CA = 5.0", "CA = 0.0"), ("damping = 0.5", "damping = 0.0"),
                     ('effects = ["transport"', 'effects = ["unbalance", "bearing_damping", "transport"'),
                     ('name = "ac"', 'name = "ac"\ncm_offset = [0.0, 0.0]\nbearing_damping = 0.0')):
        assert old in text
        text = text.replace(old, new, 1)
    scene = loads_scene(text)
    written = dumps_scene(scene)
    for key in ("CA = 0.0", "damping = 0.0", "bearing_damping = 0.0", "cm_offset = [0.0, 0.0]"):
        assert key in written, key
    assert first_difference(scene, loads_scene(written)) is None


_BARE = """
[belt]
EA = 1.0e5
EI = 1.0e-3
rhoA = 0.1
static_tension = 300.0
[[pulley]]
name = "crank"
center = [0.0, 0.0]
radius = 0.08
mass = 1.0
inertia = 0.01
driven = true
[[pulley]]
name = "alt"
center = [0.3, 0.0]
radius = 0.03
mass = 0.5
inertia = 0.001
[tensioner]
pivot = [0.15, 0.15]
arm_length = 0.06
pulley_radius = 0.03
arm_mass = 0.3
arm_inertia = 1.0e-4
pulley_mass = 0.2
pulley_inertia = 1.0e-4
spring_stiffness = 20.0
spring_preload_deg = 30.0
[route]
order = ["crank", "tensioner", "alt"]
[[torque]]
pulley = "alt"
[[decoupler]]
pulley = "alt"
rotor_inertia = 3.0e-3
stiffness = 20.0
[isolator]
pulley = "crank"
stiffness = 300.0
[[span_load]]
span = "crank-tensioner"
node = 1
amplitude_N = 1.0
frequency_hz = 10.0
[simulation]
"""


def _defaulted(sc, key):
    """The parsed scene's value of the scene-file key ``group.name`` (first of an array table)."""
    group, name = key.split(".")
    holder = {"belt": sc.belt, "pulley": sc.pulleys[0], "tensioner": sc.tensioner, "route": sc.route,
              "model": sc.model, "simulation": sc.simulation, "isolator": sc.isolator,
              "torque": sc.torques[0], "decoupler": sc.decouplers[0], "span_load": sc.span_loads[0]}.get(group)
    return None if holder is None else getattr(holder, name)


def test_defaults_are_stated_once_and_read_written_and_built_alike():
    """Each default is stated once (beltjax.schema.DEFAULTS): a scene file missing every optional key
    reads to exactly those values, the spec's pytrees default to them, and the writer leaves them out."""
    from beltjax import schema
    from beltjax.scene import spec

    sc = loads_scene(_BARE)
    checked = 0
    for key, d in schema.DEFAULTS.items():
        assert key in schema.FIELDS or key.split(".")[0] in ("route", "model", "simulation"), key
        v = _defaulted(sc, key)
        if v is None and key.startswith("fluctuation."):
            continue  # (a harmonic needs its amplitude: checked with the fluctuation below)
        got = np.asarray(v).tolist() if not isinstance(v, (str, tuple)) else v
        assert got == (list(d) if isinstance(d, tuple) and not isinstance(v, tuple) else d), (key, v, d)
        checked += 1
    assert checked == len(schema.DEFAULTS) - 1
    for cls, group in ((spec.Belt, "belt"), (spec.Tensioner, "tensioner"), (spec.Decoupler, "decoupler"),
                       (spec.Isolator, "isolator"), (spec.Simulation, "simulation")):
        for f in dataclasses.fields(cls):
            key = f"{group}.{f.name}"
            if f.default is not dataclasses.MISSING and f.default is not None and (key in schema.FIELDS
                                                                                  or group == "simulation"):
                assert key in schema.DEFAULTS and f.default == schema.DEFAULTS[key], key
    doc = tomllib.loads(dumps_scene(sc))
    for key in schema.DEFAULTS:
        group, name = key.split(".")
        table = doc.get(group, {})
        for i, t in enumerate(table if isinstance(table, list) else [table]):
            if group in ("route", "model") or (key == "pulley.speed_rpm" and i == 0):
                continue  # (written whole: the file names its route, model and drive speed)
            assert name not in t, key
    flu = loads_scene(_BARE.replace("[simulation]", '[model]\neffects = ["speed_fluctuation"]\n'
                                    '[[fluctuation]]\npulley = "crank"\norder = 2.0\namplitude_deg = 0.5\n'
                                    '[simulation]'))
    assert float(flu.fluctuations[0].phase_deg) == schema.DEFAULTS["fluctuation.phase_deg"]
