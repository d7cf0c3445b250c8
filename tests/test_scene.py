"""Scene files: the example scenes, the pytree they load into, and one-line errors."""

import math
import pathlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import geometry
from beltjax.scene import EFFECTS, Scene, SceneError, load_scene, loads_scene, parse_scene

SCENES = pathlib.Path(__file__).resolve().parents[1] / "scenes"
EXAMPLES = ["two_pulley_T200.toml", "two_pulley_T400.toml", "two_pulley_T600.toml", "tensioner_bench_stage2.toml"]

TWO = """
[belt]
EA = 111190.0
EI = 0.034
rhoA = 0.12101
static_tension = 600.0

[[pulley]]
name = "crank"
center = [0.8973, 0.2]
radius = 0.1015
mass = 7.8269
inertia = 32.651e-3
driven = true
speed_rpm = 0.0

[[pulley]]
name = "alternator"
center = [0.2208, 0.135]
radius = 0.0375
mass = 2.1543
inertia = 1.7019e-3

[route]
order = ["crank", "alternator"]
back_side = []
direction = "cw"

[model]
fidelity = "ancf"
elements_per_span = 16
effects = ["transport"]
"""

TENS = """
[belt]
EA = 111190.0
EI = 0.034
rhoA = 0.12101
length = 1.7929

[[pulley]]
name = "crank"
center = [0.8973, 0.2]
radius = 0.1015
mass = 7.8269
inertia = 32.651e-3
driven = true

[[pulley]]
name = "alternator"
center = [0.2425, 0.135]
radius = 0.0375
mass = 2.1543
inertia = 1.7019e-3

[tensioner]
pivot = [0.64335, 0.0884]
arm_length = 0.094
pulley_radius = 0.037
arm_mass = 1.0554
arm_inertia = 0.9969e-3
pulley_mass = 0.2638
pulley_inertia = 0.1806e-3
spring_stiffness = 21.14
spring_preload_deg = 94.5

[route]
order = ["crank", "tensioner", "alternator"]
back_side = ["tensioner"]
"""


def _sub(text, old, new):
    assert old in text, old
    return text.replace(old, new, 1)


# --------------------------------------------------------------------------- examples


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_scenes_load(name):
    scene = load_scene(SCENES / name)
    assert isinstance(scene, Scene)
    assert scene.source.endswith(name)
    geo = scene.geometry()  # checked geometry at the given / initial arm angle
    assert np.all(np.isfinite(np.asarray(geo.span_length)))
    assert scene.description


@pytest.mark.parametrize("T", [200, 400, 600])
def test_two_pulley_scenes_follow_the_reference(ref, T):
    scene = load_scene(SCENES / f"two_pulley_T{T}.toml")
    bench = ref["bench"]
    case = next(c for c in ref["two_pulley_bench"]["modal"]["cases"] if c["T"] == T)
    crank, alt = scene.pulley("crank"), scene.pulley("alternator")
    np.testing.assert_array_equal(crank.center, bench["crank_pulley"]["center"])
    np.testing.assert_array_equal(alt.center, [case["X_A"], bench["alternator_pulley"]["center_y"]])
    for p, key in ((crank, "crank_pulley"), (alt, "alternator_pulley")):
        for field in ("radius", "mass", "inertia"):
            assert float(getattr(p, field)) == bench[key][field]
    assert not crank.driven and not alt.driven  # free, as in the thesis' modal tests (rigid mode at 0 Hz)
    for field in ("EA", "EI", "rhoA"):
        assert float(getattr(scene.belt, field)) == bench["belt"][field]
    assert float(scene.belt.static_tension) == T and scene.belt.length is None
    assert scene.tensioner is None
    assert scene.route.order == ("crank", "alternator") and scene.route.back_side == ()
    assert scene.model.elements_per_span == 16 and scene.model.fidelity == "ancf"


def test_tensioner_scene_follows_the_reference(ref):
    scene = load_scene(SCENES / "tensioner_bench_stage2.toml")
    t, bt = scene.tensioner, ref["bench"]["tensioner"]
    for field in ("arm_length", "pulley_radius", "arm_mass", "arm_inertia", "pulley_mass", "pulley_inertia"):
        assert float(getattr(t, field)) == bt[field]
    np.testing.assert_array_equal(t.pivot, bt["pivot"])
    assert float(t.spring_stiffness) == bt["spring_stiffness_Nm_per_rad"]
    stage2 = ref["tensioner_bench_stage2"]
    assert float(t.spring_preload_deg) == stage2["spring_preload_deg"]
    assert float(scene.pulley("alternator").center[0]) == 0.2425
    assert scene.route.order == ("crank", "tensioner", "alternator")
    assert scene.route.back_side == ("tensioner",)
    assert scene.belt.static_tension is None
    # the belt length is the path at the installation angle (belt fits unstretched there)
    theta_i = math.radians(stage2["installation"]["belt_fits_unstretched_at_arm_angle_deg"])
    assert abs(float(scene.geometry(theta_i).length) - float(scene.belt.length)) < 1e-9
    # ... and it lies in the range calibrated on the two-pulley bench, L0 = L_path / (1 + T/EA)
    EA = float(scene.belt.EA)
    L0 = []
    for case in ref["two_pulley_bench"]["modal"]["cases"]:
        D = math.hypot(0.8973 - case["X_A"], 0.2 - 0.135)
        L0.append(float(geometry.two_pulley_length(D, 0.1015, 0.0375)) / (1 + case["T"] / EA))
    assert min(L0) - 1e-4 < float(scene.belt.length) < max(L0) + 1e-4
    # at the thesis' equilibrium angles the idler is on the lower strand, wrapped by the back
    for deg in (stage2["static"]["arm_angle_deg_modal_section"], stage2["static"]["arm_angle_deg_rotational_model"]):
        geo = scene.geometry(math.radians(deg))
        assert scene.route.senses.tolist() == [-1, 1, -1]
        assert 0 < float(geo.arrive_angle[1]) < math.pi and 0 < float(geo.depart_angle[1]) < math.pi
        assert 0 < float(geo.wrap[1]) < math.pi / 2


def test_defaults_and_dict_input():
    data = {
        "belt": {"EA": 1e5, "EI": 0.03, "rhoA": 0.1, "static_tension": 300},
        "pulley": [
            {"name": "a", "center": [0, 0], "radius": 0.1, "mass": 1, "inertia": 1e-3, "driven": True},
            {"name": "b", "center": [0.5, 0], "radius": 0.05, "mass": 1, "inertia": 1e-3},
        ],
        "route": {"order": ["a", "b"]},
    }
    scene = parse_scene(data)
    assert scene.source == "<dict>"
    assert scene.route.direction == "cw" and scene.route.back_side == ()
    assert scene.model.fidelity == "ancf" and scene.model.elements_per_span == 16
    assert scene.model.effects == () and not scene.model.has("transport")
    assert float(scene.belt.CA) == 0.0
    b = scene.pulley("b")
    assert float(b.speed_rpm) == 0.0 and not b.driven
    np.testing.assert_array_equal(b.cm_offset, [0.0, 0.0])
    assert scene.pulley("a").center.dtype == jnp.float64
    with pytest.raises(ValueError):
        scene.model.has("warp_drive")
    assert set(EFFECTS) >= {"transport", "gravity", "belt_damping", "bearing_damping", "tensioner_damping", "unbalance"}


def test_string_and_file_give_the_same_scene(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text(TWO)
    a, b = load_scene(f), loads_scene(TWO)
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    assert len(la) == len(lb) and all(np.array_equal(x, y) for x, y in zip(la, lb))
    assert a.model.has("transport")


def test_scene_is_a_pytree_for_gradients():
    """Gradients reach centres, radii and the tensioner arm through the scene."""
    scene = loads_scene(TENS)

    def length(s):
        return s.geometry(jnp.deg2rad(46.5), check=False).length

    grads = eqx.filter_grad(length)(scene)
    g_x = float(grads.pulleys[1].center[0])
    g_arm = float(grads.tensioner.arm_length)
    g_r = float(grads.tensioner.pulley_radius)
    h = 1e-6

    def fd(where, delta):
        plus = eqx.tree_at(where, scene, where(scene) + delta)
        minus = eqx.tree_at(where, scene, where(scene) - delta)
        return float(length(plus) - length(minus)) / (2 * h)

    assert abs(g_x - fd(lambda s: s.pulleys[1].center, jnp.array([h, 0.0]))) < 1e-8
    assert abs(g_arm - fd(lambda s: s.tensioner.arm_length, h)) < 1e-8
    assert abs(g_r - fd(lambda s: s.tensioner.pulley_radius, h)) < 1e-8
    assert g_x < 0  # moving the alternator right shortens the belt
    # and jit with the scene as an argument
    assert abs(float(eqx.filter_jit(length)(scene)) - float(length(scene))) < 1e-15


def test_layout_needs_an_arm_angle():
    scene = loads_scene(TENS)
    with pytest.raises(ValueError, match="arm_angle_deg"):
        scene.layout()
    c, r = scene.layout(jnp.deg2rad(46.5))
    assert c.shape == (3, 2) and r.shape == (3,)
    scene2 = loads_scene(_sub(TENS, "spring_preload_deg = 94.5", "spring_preload_deg = 94.5\narm_angle_deg = 46.5"))
    np.testing.assert_allclose(scene2.layout()[0], c, atol=1e-15)


# --------------------------------------------------------------------------- bad scenes

# (id, TOML text, key path the message must start with, fragment it must contain)
BAD = [
    (
        "both T and L",
        _sub(TWO, "static_tension = 600.0", "static_tension = 600.0\nlength = 1.79"),
        "belt",
        "exactly one",
    ),
    ("neither T nor L", _sub(TWO, "static_tension = 600.0", ""), "belt", "exactly one of static_tension and length"),
    ("negative radius", _sub(TWO, "radius = 0.0375", "radius = -0.01"), "pulley[1].radius", "must be > 0, got -0.01"),
    (
        "unknown route name",
        _sub(TWO, '"crank", "alternator"]', '"crank", "alt"]'),
        "route.order",
        "unknown pulley 'alt'",
    ),
    ("string for number", _sub(TWO, "EA = 111190.0", 'EA = "111190"'), "belt.EA", "expected a number, got a string"),
    ("nan", _sub(TWO, "EI = 0.034", "EI = nan"), "belt.EI", "must be finite"),
    ("inf", _sub(TWO, "rhoA = 0.12101", "rhoA = inf"), "belt.rhoA", "must be finite"),
    ("typo key", _sub(TWO, "EA = 111190.0", "EAA = 111190.0"), "belt.EAA", "unknown key"),
    ("typo table", _sub(TWO, "[model]", "[modle]"), "modle", "unknown key (allowed at the top level"),
    (
        "typo pulley key",
        _sub(TWO, "inertia = 1.7019e-3", "inertia = 1.7019e-3\nradious = 0.1"),
        "pulley[1].radious",
        "unknown key",
    ),
    (
        "duplicated name",
        _sub(TWO, 'name = "alternator"', 'name = "crank"'),
        "pulley[1].name",
        "duplicated name 'crank'",
    ),
    (
        "tensioner route without table",
        _sub(TWO, '"crank", "alternator"]', '"crank", "tensioner", "alternator"]'),
        "route.order",
        "no [tensioner] table",
    ),
    (
        "tensioner table not routed",
        _sub(TENS, '"crank", "tensioner", "alternator"]', '"crank", "alternator"]'),
        "route.order",
        "'tensioner' is not in the route",
    ),
    (
        "pulley not routed",
        TWO + '\n[[pulley]]\nname = "ps"\ncenter = [0.5, 0.5]\nradius = 0.05\nmass = 1.0\ninertia = 1e-3\n',
        "route.order",
        "pulley 'ps' is not in the route",
    ),
    ("negative mass", _sub(TWO, "mass = 7.8269", "mass = -7.8269"), "pulley[0].mass", "must be >= 0"),
    ("negative inertia", _sub(TWO, "inertia = 1.7019e-3", "inertia = -1.7019e-3"), "pulley[1].inertia", "must be > 0"),
    (
        "negative stiffness",
        _sub(TENS, "spring_stiffness = 21.14", "spring_stiffness = -21.14"),
        "tensioner.spring_stiffness",
        "must be > 0",
    ),
    (
        "negative arm inertia",
        _sub(TENS, "arm_inertia = 0.9969e-3", "arm_inertia = -1e-3"),
        "tensioner.arm_inertia",
        "must be >= 0",
    ),
    ("tensioner missing key", _sub(TENS, "arm_length = 0.094", ""), "tensioner.arm_length", "missing"),
    (
        "zero elements",
        _sub(TWO, "elements_per_span = 16", "elements_per_span = 0"),
        "model.elements_per_span",
        "must be >= 1",
    ),
    (
        "float elements",
        _sub(TWO, "elements_per_span = 16", "elements_per_span = 16.0"),
        "model.elements_per_span",
        "expected an integer",
    ),
    (
        "unknown fidelity",
        _sub(TWO, 'fidelity = "ancf"', 'fidelity = "fem"'),
        "model.fidelity",
        "must be one of 'ancf', 'rotational'",
    ),
    (
        "unknown effect",
        _sub(TWO, 'effects = ["transport"]', 'effects = ["trasport"]'),
        "model.effects",
        "unknown effect 'trasport'",
    ),
    (
        "three-number centre",
        _sub(TWO, "center = [0.8973, 0.2]", "center = [0.8973, 0.2, 0.0]"),
        "pulley[0].center",
        "expected [x, y]",
    ),
    (
        "string in centre",
        _sub(TWO, "center = [0.8973, 0.2]", 'center = [0.8973, "y"]'),
        "pulley[0].center",
        "element 1 is a string",
    ),
    ("missing radius", _sub(TWO, "radius = 0.0375", ""), "pulley[1].radius", "missing (required key)"),
    (
        "bad direction",
        _sub(TWO, 'direction = "cw"', 'direction = "clockwise"'),
        "route.direction",
        "must be one of 'cw', 'ccw'",
    ),
    (
        "back side not routed",
        _sub(TWO, "back_side = []", 'back_side = ["idler"]'),
        "route.back_side",
        "'idler' is not in route.order",
    ),
    (
        "repeated route entry",
        _sub(TWO, '"crank", "alternator"]', '"crank", "alternator", "crank"]'),
        "route.order",
        "'crank' appears twice",
    ),
    (
        "overlapping pulleys",
        _sub(TWO, "center = [0.2208, 0.135]", "center = [0.8, 0.135]"),
        "pulley[1].center",
        "'crank' and 'alternator' overlap",
    ),
    (
        "speed on free pulley",
        _sub(TWO, "inertia = 1.7019e-3", "inertia = 1.7019e-3\nspeed_rpm = 100.0"),
        "pulley[1].speed_rpm",
        "only the drive pulley",
    ),
    ("boolean as string", _sub(TWO, "driven = true", 'driven = "yes"'), "pulley[0].driven", "expected true or false"),
    (
        "boolean for number",
        _sub(TWO, "mass = 7.8269", "mass = true"),
        "pulley[0].mass",
        "expected a number, got a boolean",
    ),
    ("reserved name", _sub(TWO, 'name = "alternator"', 'name = "tensioner"'), "pulley[1].name", "reserved"),
    (
        "pulley as table",
        TWO.split("[[pulley]]")[0] + "[pulley]" + TWO.split("[[pulley]]")[1],
        "pulley",
        "expected an array of tables",
    ),
    ("no route", TWO.split("[route]")[0], "route", "missing"),
    ("slack belt", _sub(TWO, "static_tension = 600.0", "length = 1.81"), "belt.length", "slack"),
    (
        "negative tension",
        _sub(TWO, "static_tension = 600.0", "static_tension = -600.0"),
        "belt.static_tension",
        "must be > 0",
    ),
    ("belt not a table", "belt = 5\n[[pulley]]" + TWO.split("[[pulley]]", 1)[1], "belt", "expected a table"),
    ("description type", "description = 5\n" + TWO, "description", "expected a string"),
    (
        "idler on the inner side",
        _sub(
            _sub(TENS, 'back_side = ["tensioner"]', "back_side = []"),
            "spring_preload_deg = 94.5",
            "spring_preload_deg = 94.5\narm_angle_deg = 46.5",
        ),
        "route.order",
        "cross each other",
    ),
    ("route of one", _sub(TWO, '"crank", "alternator"]', '"crank"]'), "route.order", "at least two"),
    # transient tables and effect switches
    (
        "torque on a driven pulley",
        TWO + '[[torque]]\npulley = "crank"\nmean_Nm = 5.0\n',
        "torque[0].pulley",
        "not a free pulley",
    ),
    (
        "torque window reversed",
        TWO + '[[torque]]\npulley = "alternator"\nmean_Nm = 5.0\nt_start_s = 2.0\nt_end_s = 1.0\n',
        "torque[0].t_end_s",
        "later than t_start_s",
    ),
    ("torque not an array", TWO + '[torque]\npulley = "alternator"\n', "torque", "expected an array of tables"),
    (
        "span load on the rotational model",
        _sub(TWO, 'fidelity = "ancf"', 'fidelity = "rotational"')
        + '[[span_load]]\nspan = "crank-alternator"\nnode = 8\namplitude_N = 0.1\nfrequency_hz = 50.0\n',
        "span_load[0].span",
        "needs the hybrid model",
    ),
    (
        "span load on an end node",
        TWO + '[[span_load]]\nspan = "crank-alternator"\nnode = 16\namplitude_N = 0.1\nfrequency_hz = 50.0\n',
        "span_load[0].node",
        "interior node",
    ),
    (
        "span load on an unknown span",
        TWO + '[[span_load]]\nspan = "crank-idler"\nnode = 8\namplitude_N = 0.1\nfrequency_hz = 50.0\n',
        "span_load[0].span",
        "unknown span",
    ),
    (
        "initial rotation of the driven pulley",
        TWO + "[initial]\nrotation_deg = { crank = 2.0 }\n",
        "initial.rotation_deg.crank",
        "not a free pulley",
    ),
    ("initial arm without tensioner", TWO + "[initial]\narm_angle_deg = 40.0\n", "initial.arm_angle_deg", "no [tensioner]"),
    ("unknown solver", TWO + '[simulation]\nsolver = "euler"\n', "simulation.solver", "must be one of"),
    ("rho_inf out of range", TWO + "[simulation]\nrho_inf = 1.5\n", "simulation.rho_inf", "must lie in [0, 1]"),
    ("negative step", TWO + "[simulation]\ndt_s = -1e-4\n", "simulation.dt_s", "must be > 0"),
    ("bad output node", TWO + '[simulation]\nnodes = ["crank-alternator:40"]\n', "simulation.nodes", "is not"),
    ("damping not switched on", _sub(TWO, "rhoA = 0.12101", "rhoA = 0.12101\nCA = 5.0"), "belt.CA", "belt_damping"),
    (
        "unbalance not switched on",
        _sub(TWO, "inertia = 1.7019e-3", "inertia = 1.7019e-3\ncm_offset = [0.001, 0.0]"),
        "pulley[1].cm_offset",
        "unbalance",
    ),
    (
        "fluctuation not switched on",
        _sub(TWO, "speed_rpm = 0.0", "speed_rpm = 600.0\nfluctuation_amplitude_deg = 1.0\nfluctuation_frequency_hz = 20.0"),
        "pulley[0].fluctuation_amplitude_deg",
        "speed_fluctuation",
    ),
    (
        "fluctuation without frequency",
        _sub(TWO, "speed_rpm = 0.0", "speed_rpm = 600.0\nfluctuation_amplitude_deg = 1.0"),
        "pulley[0].fluctuation_frequency_hz",
        "missing",
    ),
    (
        "target speed without run-up",
        _sub(TWO, "speed_rpm = 0.0", "speed_rpm = 600.0\ntarget_speed_rpm = 2000.0"),
        "pulley[0].target_speed_rpm",
        "needs acceleration_rpm_per_s",
    ),
    (
        "target speed behind",
        _sub(TWO, "speed_rpm = 0.0", "speed_rpm = 600.0\nacceleration_rpm_per_s = 100.0\ntarget_speed_rpm = 300.0"),
        "pulley[0].target_speed_rpm",
        "cannot be reached",
    ),
]


@pytest.mark.parametrize("text,key,fragment", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_scene_raises_one_line_error_naming_the_key(text, key, fragment):
    with pytest.raises(SceneError) as info:
        loads_scene(text)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(key + ":"), msg
    assert fragment in msg, msg
    assert info.value.key == key
    assert isinstance(info.value, ValueError)


def test_at_least_twenty_bad_scenes():
    assert len(BAD) >= 20


def test_malformed_toml_names_file_and_line(tmp_path):
    f = tmp_path / "broken.toml"
    f.write_text("[belt]\nEA = 111190.0\nEI = = 0.034\n")
    with pytest.raises(SceneError) as info:
        load_scene(f)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(f)) and "line 3" in msg


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match="not found") as info:
        load_scene(tmp_path / "nope.toml")
    assert "\n" not in str(info.value)
    with pytest.raises(SceneError, match="directory"):
        load_scene(tmp_path)


def test_transient_tables_parse():
    text = (
        _sub(TWO, "speed_rpm = 0.0", "speed_rpm = 600.0\nacceleration_rpm_per_s = 100.0\ntarget_speed_rpm = 900.0")
        + '[[torque]]\npulley = "alternator"\nmean_Nm = -20.0\namplitude_Nm = -5.0\nfrequency_hz = 2.0\n'
        + "t_start_s = 1.0\nt_end_s = 5.0\n"
        + '[[span_load]]\nspan = "alternator-crank"\nnode = 8\namplitude_N = 0.02\nfrequency_hz = 52.3\n'
        + '[initial]\nrotation_deg = { alternator = 2.0 }\n[simulation]\nsolver = "tsit5"\ndt_s = 2e-4\n'
        + 'nodes = ["crank-alternator:4"]\n'
    )
    sc = loads_scene(text)
    (tq,) = sc.torques
    assert tq.pulley == "alternator" and float(tq.mean_Nm) == -20.0 and float(tq.t_end_s) == 5.0
    (ld,) = sc.span_loads
    assert ld.span == "alternator-crank" and ld.node == 8 and float(ld.frequency_hz) == 52.3
    assert sc.initial.rotation_deg == (("alternator", 2.0),)
    assert sc.simulation.solver == "tsit5" and sc.simulation.dt_s == 2e-4
    assert sc.simulation.nodes == ("crank-alternator:4",)
    assert float(sc.pulleys[0].target_speed_rpm) == 900.0
