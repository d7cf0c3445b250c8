"""Robustness to bad input: one table of broken inputs across every ``beltjax`` command.

Each row is a realistic mistake (a broken copy of a shipped scene, sweep, optimisation or
identification file written into ``tmp_path``, or a bad command-line argument) for one of
``beltjax statics | modal | campbell | simulate | span | fit | sweep | optimize``.  For every
row the test checks that the command

* exits with status 2 (the status of an input error; 1 would mean an unexpected exception
  caught by the last-resort handler),
* writes exactly one non-empty line to stderr, starting with ``beltjax: error:``, with no
  ``Traceback``, that contains the expected text naming the offending key or the cause,
* writes no result file (so in particular no result with NaN in it).

Most rows run ``beltjax.cli.main`` in-process; a few run the installed console script or
``python -m beltjax.cli`` in a subprocess to check the real exit status and stderr.  Nearly
all errors come from validation before any JIT compilation; the rows marked ``compiles``
(at most two) fail in the installation of the belt, after a small compilation.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import shutil
import signal
import subprocess
import sys
from typing import Callable

import pytest

from beltjax.cli import main

REPO = pathlib.Path(__file__).resolve().parents[1]
SCENES = REPO / "scenes"
EXAMPLES = REPO / "identification" / "examples"
T200_PATH = SCENES / "two_pulley_T200.toml"
T200 = T200_PATH.read_text()
BENCH_PATH = SCENES / "tensioner_bench_stage2.toml"
BENCH = BENCH_PATH.read_text()
SWEEP = (SCENES / "sweeps" / "two_pulley_tension_EI.toml").read_text()
TOLERANCE = (SCENES / "sweeps" / "two_pulley_tolerance.toml").read_text()
OPTIMIZE = (SCENES / "optimize" / "tensioner_pivot.toml").read_text()
TORQUE_ANGLE = (EXAMPLES / "tensioner_torque_angle" / "dataset.toml").read_text()
TORQUE_ANGLE_CSV = (EXAMPLES / "tensioner_torque_angle" / "torque_angle.csv").read_text()
IMPULSE = (EXAMPLES / "impulse" / "dataset.toml").read_text()
IMPULSE_CSV = (EXAMPLES / "impulse" / "tensioner_arm.csv").read_text()
TENSILE = (EXAMPLES / "tensile_belt_A" / "dataset.toml").read_text()
SPAN = ["span", "--length", "0.67", "--tension", "100", "--EA", "111190", "--EI", "0.034", "--rhoA", "0.121"]
PREFIX = "beltjax: error: "
MAX_COMPILING = 2  # rows allowed to fail only after a JIT compilation (they cost seconds each)


def edit(text: str, *changes: tuple[str, str]) -> str:
    """``text`` with each (old, new) replaced once; the old text must be there (no silent no-op)."""
    for old, new in changes:
        assert old in text, f"{old!r} is no longer in the example file"
        text = text.replace(old, new, 1)
    return text


def write(d: pathlib.Path, name: str, text: str | bytes) -> str:
    p = d / name
    p.parent.mkdir(parents=True, exist_ok=True)
    (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    return str(p)


def scene(d, *changes, base=T200):
    return write(d, "scene.toml", edit(base, *changes))


def fead_trace(d, csv: str) -> str:
    """The eight-pulley drive with its crank fluctuation read from the trace ``csv`` (crank.csv)."""
    write(d, "crank.csv", csv)
    return write(d, "scene.toml", (SCENES / "fead_8pulley.toml").read_text()
                 + '\n[[fluctuation]]\npulley = "crank"\nfile = "crank.csv"\n')


def bench(d, *changes):
    return scene(d, *changes, base=BENCH)


def dataset(d, text, **csv):
    """A dataset.toml with CSV files next to it (file name with '.' written as '_')."""
    for name, body in csv.items():
        write(d / "data", name.replace("_csv", ".csv"), body)
    return write(d / "data", "dataset.toml", text)


def modal_dataset(d, scene_path, label="1st transverse", frequency=30.0):
    """A modal dataset whose scene is a copy of ``scene_path`` in its folder (a dataset names only
    files inside its own folder)."""
    write(d / "data", "scene.toml", pathlib.Path(scene_path).read_text())
    return dataset(d, f'[modal]\nparameters = ["belt.EI"]\n\n[[modal.configuration]]\nname = "T200"\n'
                      f'scene = "scene.toml"\nmodes = [{{ label = "{label}", frequency_hz = {frequency} }}]\n')


MIB = 1 << 20
PLANTED = "PLANTED-7f3a-CONTENT"  # a distinctive text in a file's contents: no error message may quote it


def fifo(d: pathlib.Path, name: str) -> str:
    """A named pipe (nothing ever writes to it: opening it for reading would block)."""
    p = d / name
    p.parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(p)
    return str(p)


def sparse(d: pathlib.Path, name: str, size: int) -> str:
    """A file of ``size`` bytes (zeros; sparse, so it costs no disk)."""
    p = d / name
    p.parent.mkdir(parents=True, exist_ok=True)
    with open(p, "wb") as f:
        f.truncate(size)
    return str(p)


def link(d: pathlib.Path, name: str, target: pathlib.Path) -> str:
    p = d / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.symlink_to(target)
    return str(p)


def torque_angle_named(d, file_name, **csv):
    """The torque-angle dataset naming ``file_name`` for its CSV; the real CSV (with a planted text)
    is written next to the data folder, outside it."""
    write(d, "torque_angle.csv", TORQUE_ANGLE_CSV + f"# {PLANTED}\n")
    return dataset(d, edit(TORQUE_ANGLE, ('"torque_angle.csv"', f'"{file_name}"')), **csv)


def two_configurations(d, second_name="T200", parameters='["belt.EI"]'):
    """A modal dataset of two configurations (same scene) with the given second name."""
    write(d / "data", "scene.toml", T200)
    conf = '[[modal.configuration]]\nname = "{}"\nscene = "scene.toml"\nmodes = [{{ label = "1st transverse", frequency_hz = 30.0 }}]\n'
    return dataset(d, f"[modal]\nparameters = {parameters}\n\n" + conf.format("T200") + conf.format(second_name))


@dataclasses.dataclass(frozen=True)
class Case:
    id: str
    input: str  # what is given (for the README table)
    wrong: str  # what is wrong with it
    argv: Callable[[pathlib.Path], list[str]]  # tmp_path -> command line (without --out)
    expect: tuple[str, ...]  # texts the error line must contain (the key or cause)
    how: str = "main"  # "main": in-process; "script": console script; "module": python -m beltjax.cli
    compiles: bool = False  # fails only after a JIT compilation


def case(id, input, wrong, argv, *expect, how="main", compiles=False):
    return Case(id, input, wrong, argv, tuple(expect), how, compiles)


T2 = str(T200_PATH)
FEAD = (SCENES / "fead_8pulley.toml").read_text()
TB = str(BENCH_PATH)


def t200_slip(d):
    """The hybrid two-pulley bench (T = 200 N) with belt_slip and a friction coefficient, written to d."""
    return write(d, "scene.toml", edit(T200, ("static_tension = 200.0 ", "friction_coefficient = 0.3\nstatic_tension = 200.0 "),
                                       ('effects = ["transport"]', 'effects = ["transport", "belt_slip"]')))
CASES = [
    # ---------------------------------------------------------------- scene files (statics)
    case("scene-malformed-toml", "`statics`: `EA = 111190.0 N`", "malformed TOML (a unit after the number)",
         lambda d: ["statics", scene(d, ("EA = 111190.0", "EA = 111190.0 N"))],
         "malformed TOML", "line 8", how="script"),
    case("scene-not-found", "`statics no_such_scene.toml`", "nonexistent file",
         lambda d: ["statics", str(d / "no_such_scene.toml")], "no_such_scene.toml", "scene file not found"),
    case("scene-empty-file", "`statics` on an empty file", "empty scene file",
         lambda d: ["statics", write(d, "empty.toml", "")], "belt: missing"),
    case("scene-directory", "`statics` on a directory", "a directory, not a file",
         lambda d: ["statics", str(d)], "is a directory"),
    case("scene-not-utf8", "`statics` on binary bytes", "not a text file",
         lambda d: ["statics", write(d, "binary.toml", b"\xff\xfe\x00\x01belt")], "not a UTF-8 text file"),
    case("scene-empty-argument", "`statics \"\"`", "empty file name",
         lambda d: ["statics", ""], "argument scene: empty file name"),
    case("scene-string-for-number", "`statics`: `EA = \"111190\"`", "string for a number",
         lambda d: ["statics", scene(d, ("EA = 111190.0", 'EA = "111190"'))], "belt.EA: expected a number"),
    case("scene-boolean-for-number", "`statics`: `mass = true`", "boolean for a number",
         lambda d: ["statics", scene(d, ("mass = 2.1543", "mass = true"))], "pulley[1].mass: expected a number"),
    case("scene-negative-mass", "`statics`: `mass = -2.1543`", "negative mass",
         lambda d: ["statics", scene(d, ("mass = 2.1543", "mass = -2.1543"))], "pulley[1].mass: must be >= 0"),
    case("scene-zero-friction", "`statics`: `friction_coefficient = 0.0`", "a friction coefficient that is not positive",
         lambda d: ["statics", scene(d, ("static_tension = 200.0", "static_tension = 200.0\nfriction_coefficient = 0.0"))],
         "belt.friction_coefficient: must be > 0"),
    case("scene-implausible-friction", "`statics`: `friction_coefficient = 12.0` on a pulley", "implausible friction",
         lambda d: ["statics", scene(d, ("inertia = 1.7019e-3", "inertia = 1.7019e-3\nfriction_coefficient = 12.0"))],
         "pulley[1].friction_coefficient: must lie in [0.001, 5]"),
    case("statics-load-no-belt-carries", "`statics` of the eight-pulley drive with 15.5 N m on a back-side idler",
         "a load no belt could carry",
         lambda d: ["statics", write(d, "scene.toml", FEAD + '\n[[torque]]\npulley = "idler_top"\nmean_Nm = 15.5\n')],
         "statics: pulley 'idler_top' would need a friction coefficient of 5.5", "no belt could"),
    case("scene-negative-tension", "`statics`: `static_tension = -200.0`", "negative tension",
         lambda d: ["statics", scene(d, ("static_tension = 200.0", "static_tension = -200.0"))],
         "belt.static_tension: must be > 0"),
    case("scene-nan", "`statics`: `EI = nan`", "NaN", lambda d: ["statics", scene(d, ("EI = 0.034", "EI = nan"))],
         "belt.EI: must be finite"),
    case("scene-inf", "`statics`: `radius = inf`", "infinite value",
         lambda d: ["statics", scene(d, ("radius = 0.0375", "radius = inf"))], "pulley[1].radius: must be finite"),
    case("scene-nan-in-vector", "`statics`: `center = [0.2232, -nan]`", "NaN in a vector",
         lambda d: ["statics", scene(d, ("center = [0.2232, 0.135]", "center = [0.2232, -nan]"))],
         "pulley[1].center: must be finite"),
    case("scene-vector-as-string", "`statics`: `center = \"0.2232, 0.135\"`", "string for [x, y]",
         lambda d: ["statics", scene(d, ("center = [0.2232, 0.135]", 'center = "0.2232, 0.135"'))],
         "pulley[1].center: expected [x, y] (two numbers), got a string"),
    case("scene-missing-key", "`statics`: no `rhoA`", "missing key",
         lambda d: ["statics", scene(d, ("rhoA = 0.12101", ""))], "belt.rhoA: missing"),
    case("scene-missing-table", "`statics`: no `[route]`", "missing table",
         lambda d: ["statics", write(d, "scene.toml", T200.split("[route]")[0])], "route: missing"),
    case("scene-tension-and-length", "`statics`: both `static_tension` and `length`", "over-determined belt",
         lambda d: ["statics", scene(d, ("static_tension = 200.0", "static_tension = 200.0\nlength = 1.79"))],
         "belt: give exactly one of static_tension and length"),
    case("scene-overlapping-pulleys", "`statics`: alternator at `[0.80, 0.2]`", "pulleys overlap",
         lambda d: ["statics", scene(d, ("center = [0.2232, 0.135]", "center = [0.80, 0.2]"))],
         "pulley[1].center", "overlap"),
    case("scene-belt-too-short-EA-in-kN", "`statics`: `EA = 111.19` (kN instead of N)",
         "EA in the wrong unit (no magnitude check of its own: the belt cannot be installed)",
         lambda d: ["statics", scene(d, ("EA = 111190.0", "EA = 111.19"))],
         "belt.static_tension", "belt too short to fit", compiles=True),
    case("scene-slack-belt", "`statics`: `length = 2.5` on fixed centres", "belt longer than its path",
         lambda d: ["statics", scene(d, ("static_tension = 200.0", "length = 2.5"))],
         "belt.length", "the belt would be slack"),
    case("scene-tensioner-cannot-reach", "`statics`: tensioner `arm_length = 0.01`",
         "the arm is too short to take up the belt at any angle",
         lambda d: ["statics", bench(d, ("arm_length = 0.094", "arm_length = 0.01"),
                                     ("arm_cm_distance = 0.0633", "arm_cm_distance = 0.005"))],
         "belt.length", "longer than the belt path at every tensioner arm angle", compiles=True),
    case("scene-idler-overlaps-crank", "`statics`: tensioner `pivot = [0.80, 0.15]`",
         "idler inside the crank pulley at the given arm angle",
         lambda d: ["statics", bench(d, ("pivot = [0.64335, 0.0884]", "pivot = [0.80, 0.15]"))],
         "tensioner.arm_angle_deg", "centre distance"),
    case("scene-tensioner-negative-friction", "`statics`: tensioner `friction_moment = -1.0`",
         "a dry-friction moment below zero (friction that drives the arm)",
         lambda d: ["statics", bench(d, ("arm_angle_deg = 46.5", "arm_angle_deg = 46.5\nfriction_moment = -1.0"),
                                     ('effects = ["transport"]', 'effects = ["transport", "tensioner_friction"]'))],
         "tensioner.friction_moment", ">= 0"),
    case("scene-tensioner-stops-reversed", "`statics`: `stop_min_deg = 60.0`, `stop_max_deg = 50.0`",
         "end stops in the wrong order",
         lambda d: ["statics", bench(d, ("arm_angle_deg = 46.5", "arm_angle_deg = 46.5\nstop_min_deg = 60.0\n"
                                                                 "stop_max_deg = 50.0"))],
         "tensioner.stop_max_deg", "must be above stop_min_deg"),
    case("scene-fluctuation-on-free-pulley", "`statics`: `[[fluctuation]] pulley = \"ac\"` (8-pulley drive)",
         "a crank order on an accessory (only the driven drive pulley's motion fluctuates)",
         lambda d: ["statics", write(d, "scene.toml", FEAD + '\n[[fluctuation]]\npulley = "ac"\norder = 2.0\n'
                                                       'amplitude_deg = 0.5\n')],
         "fluctuation[2].pulley", "not the driven drive pulley"),
    case("scene-crank-trace-one-sample", "`statics`: a crank speed trace of one sample",
         "a measured trace too short to be a cycle",
         lambda d: ["statics", fead_trace(d, "angle_deg,speed_rpm\n0.0,800.0\n")],
         "fluctuation[2].file", "1 sample"),
    case("scene-crank-trace-time-backwards", "`statics`: a crank speed trace whose time goes back",
         "non-monotonic time",
         lambda d: ["statics", fead_trace(d, "time_s,speed_rpm\n0.0,800\n0.02,801\n0.01,800\n0.03,799\n0.04,800\n")],
         "fluctuation[2].file", "must increase"),
    case("scene-fluctuation-amplitude-table", "`statics`: `rpm = [800, 2000]`, `amplitude_deg = [0.5]`",
         "a crank order's amplitude table with fewer amplitudes than speeds",
         lambda d: ["statics", write(d, "scene.toml", FEAD + '\n[[fluctuation]]\npulley = "crank"\norder = 6.0\n'
                                                       'rpm = [800.0, 2000.0]\namplitude_deg = [0.5, 0.2, 0.1]\n')],
         "fluctuation[2].amplitude_deg", "one per speed"),
    case("scene-belt-slip-hybrid", "`simulate`: `belt_slip` in a hybrid transient (two-pulley bench)",
         "creep and gross slip dynamics asked of the hybrid model's transient (its statics takes the running belt)",
         lambda d: ["simulate", t200_slip(d), "--t-end", "0.01"],
         "model.effects", "rotational model's transient"),
    case("scene-belt-slip-no-friction", "`statics`: `belt_slip` with a pulley without a friction coefficient",
         "slip asked of arcs with no friction coefficient (8-pulley drive: the belt's removed, the A/C given its own)",
         lambda d: ["statics", write(d, "scene.toml", edit(FEAD, ("friction_coefficient = 0.35 ", "# "),
                                                          ('"speed_fluctuation"]', '"speed_fluctuation", "belt_slip"]'),
                                                          ("radius = 0.060\n", "radius = 0.060\nfriction_coefficient = 1.0\n")))],
         "belt.friction_coefficient", "every wrapped arc"),
    case("orders-belt-slip-hybrid", "`orders`: `belt_slip` in a hybrid response over speed (two-pulley bench)",
         "creep and gross slip dynamics asked of the hybrid model's transient",
         lambda d: ["orders", t200_slip(d), "--rpm", "600:800:100"],
         "model.effects", "rotational model's transient"),
    case("orders-hybrid-settle-steps", "`orders --settle-s 100` of the hybrid eight-pulley drive",
         "a settling time whose fixed steps, its 4x re-run included, pass the limit (hours of the hybrid model)",
         lambda d: ["orders", write(d, "scene.toml", edit(FEAD, ('fidelity = "rotational"',
                                                                 'fidelity = "ancf"\nelements_per_span = 2'))),
                    "--rpm", "600:800:100", "--settle-s", "100"],
         "settle_s", "fixed step"),
    case("orders-load-window", "`orders`: a `[[torque]]` with `t_end_s` (8-pulley drive)",
         "a load that switches off has no steady state",
         lambda d: ["orders", write(d, "scene.toml", FEAD + '\n[[torque]]\npulley = "alternator"\nmean_Nm = 1.0\n'
                                                      't_end_s = 0.5\n'), "--rpm", "600:800:100"],
         "torque[4]", "no steady state"),
    case("orders-zero-speed", "`orders --rpm 0:1000:500`", "a crank at rest has no excitation cycle",
         lambda d: ["orders", write(d, "scene.toml", FEAD), "--rpm", "0:1000:500"], "rpm", "> 0"),
    case("orders-speed-beyond-range", "`orders --rpm 800:1e9:1e8`", "a crank speed beyond any belt-driven shaft",
         lambda d: ["orders", write(d, "scene.toml", FEAD), "--rpm", "800:1e9:1e8"], "rpm[1]", "1e+06"),
    case("orders-order-beyond-samples", "`orders --max-order 100`", "orders the cycle's samples cannot resolve",
         lambda d: ["orders", write(d, "scene.toml", FEAD), "--rpm", "600:800:100", "--max-order", "100"],
         "max_order", "samples"),
    case("scene-effect-without-parameter", "`statics`: `belt_damping` listed, no `CA` (8-pulley drive)",
         "an effect that would change nothing (as a parameter of an effect that is off)",
         lambda d: ["statics", write(d, "scene.toml", edit(FEAD, ("CA = 5.0", "# CA")))],
         "model.effects", '"belt_damping" is listed but the scene gives no belt.CA'),
    case("scene-stop-stiffness-without-stops", "`statics`: `stop_stiffness = 1000.0`, no stops (8-pulley drive)",
         "a stop's stiffness without a stop",
         lambda d: ["statics", write(d, "scene.toml", edit(FEAD, ("[tensioner]", "[tensioner]\nstop_stiffness = 1000.0")))],
         "tensioner.stop_stiffness", "there is no stop"),
    case("scene-torque-amplitude-without-frequency", "`statics`: `[[torque]] amplitude_Nm = 2.0`, no `frequency_hz`",
         "an alternating load without a frequency (it was dropped)",
         lambda d: ["statics", write(d, "scene.toml", FEAD + '\n[[torque]]\npulley = "alternator"\namplitude_Nm = 2.0\n')],
         "torque[4].frequency_hz", "give a frequency > 0"),
    case("scene-decoupler-on-driven-crank", "`statics`: `[[decoupler]] pulley = \"crank\"` (8-pulley drive)",
         "a decoupler on the driven crank (its motion is prescribed)",
         lambda d: ["statics", write(d, "scene.toml", FEAD + '\n[[decoupler]]\npulley = "crank"\n'
                                                       'rotor_inertia = 3e-3\nstiffness = 30.0\n')],
         "decoupler[0].pulley", "not a free pulley"),
    case("scene-isolator-on-accessory", "`statics`: `[isolator] pulley = \"ac\"` (8-pulley drive)",
         "an isolator on an accessory (it joins the driven crank's rim to its hub)",
         lambda d: ["statics", write(d, "scene.toml", FEAD + '\n[isolator]\npulley = "ac"\nstiffness = 300.0\n')],
         "isolator.pulley", "not the driven drive pulley"),
    case("scene-tensioner-cm-beyond-arm", "`statics`: `arm_cm_distance = 0.2` (arm 0.094 m)",
         "centre of mass beyond the arm",
         lambda d: ["statics", bench(d, ("arm_cm_distance = 0.0633", "arm_cm_distance = 0.2"))],
         "tensioner.arm_cm_distance: must not exceed arm_length"),
    case("scene-tensioner-table-missing", "`statics`: `\"tensioner\"` in the route, no `[tensioner]`",
         "missing table",
         lambda d: ["statics", write(d, "scene.toml", BENCH.split("[tensioner]")[0] + "[route]"
                                     + BENCH.split("[route]")[1])],
         "route.order", "no [tensioner] table"),
    case("scene-negative-spring", "`statics`: `spring_stiffness = -21.14`", "negative stiffness",
         lambda d: ["statics", bench(d, ("spring_stiffness = 21.14", "spring_stiffness = -21.14"))],
         "tensioner.spring_stiffness: must be > 0"),
    case("scene-EI-1e20", "`statics`: `EI = 1e20`", "a magnitude float64 cannot carry through the element matrices",
         lambda d: ["statics", scene(d, ("EI = 0.034", "EI = 1e20"))],
         "belt.EI: must lie in [0, 100000] N m^2 (", "got 1e+20"),
    case("scene-rhoA-1e-300", "`statics`: `rhoA = 1e-300`", "a mass no belt has",
         lambda d: ["statics", scene(d, ("rhoA = 0.12101", "rhoA = 1e-300"))],
         "belt.rhoA: must lie in [1e-06, 1000] kg/m (", "got 1e-300"),
    case("scene-centre-1e200", "`statics`: `center = [1e200, 0.135]`", "a centre far from the drive",
         lambda d: ["statics", scene(d, ("center = [0.2232, 0.135]", "center = [1e200, 0.135]"))],
         "pulley[1].center: must lie in [-100000, 100000] m (", "round-off of the tangent geometry"),
    case("scene-pinched-span", "`statics`: an idler 0.1 mm from the crank (its span 1e-4 m beside 0.67 m ones)",
         "a span float64 cannot carry beside the others",
         lambda d: ["statics", scene(d, ('order = ["crank", "alternator"]', 'order = ["crank", "idler", "alternator"]'),
                                     ("back_side = []", 'back_side = ["idler"]'),
                                     ("[route]", '[[pulley]]\nname = "idler"\n'
                                                 'center = [0.7834179830112434, 0.13424936345119864]\n'
                                                 'radius = 0.03\nmass = 0.3\ninertia = 0.2e-3\n\n[route]'))],
         "pulley[2].center: span crank-idler is 0.0001 m long", "float64"),
    case("out-is-a-file", "`statics scene.toml --out taken` (`taken` is a file)", "output directory is a file",
         lambda d: ["statics", T2, "--out", write(d, "taken", "x")], "--out: cannot create directory"),
    case("out-below-a-file", "`statics scene.toml --out taken/sub` (`taken` is a file)",
         "output directory below a file",
         lambda d: ["statics", T2, "--out", str(pathlib.Path(write(d, "taken", "x")) / "sub")],
         "--out: cannot create directory", "taken' is a file"),
    case("out-name-too-long", "`statics scene.toml --out xxx...x` (300 characters)",
         "an output folder name longer than the file system allows",
         lambda d: ["statics", T2, "--out", str(d / ("x" * 300))], "--out: cannot create directory",
         "too long"),
    case("scene-pulley-name-line-break", "`statics`: `name = \"alt\\nernator\"`", "a pulley name with a line break",
         lambda d: ["statics", scene(d, ('name = "alternator"', 'name = "alt\\nernator"'),
                                     ('"alternator"]', '"alt\\nernator"]'))],
         "pulley[1].name", "printable"),
    # ---------------------------------------------------------------- modal
    case("modal-huge-mesh", "`modal`: `elements_per_span = 1000000`", "mesh that cannot fit in memory",
         lambda d: ["modal", scene(d, ("elements_per_span = 16", "elements_per_span = 1000000"))],
         "model.elements_per_span: must be <= 400"),
    case("modal-unknown-effect", "`modal`: `effects = [\"transprot\"]`", "misspelt effect",
         lambda d: ["modal", scene(d, ('effects = ["transport"]', 'effects = ["transprot"]'))],
         "model.effects: unknown effect 'transprot'"),
    case("modal-unknown-route-entry", "`modal`: `order = [\"crank\", \"alternater\"]`", "route names no pulley",
         lambda d: ["modal", scene(d, ('order = ["crank", "alternator"]', 'order = ["crank", "alternater"]'))],
         "route.order: unknown pulley 'alternater'"),
    case("modal-speed-with-unit", "`modal`: `speed_rpm = \"1000 rpm\"`", "unit inside a string",
         lambda d: ["modal", scene(d, ("speed_rpm = 0.0", 'speed_rpm = "1000 rpm"'))],
         "pulley[0].speed_rpm: expected a number"),
    case("modal-rpm-inf", "`modal --rpm inf`", "infinite speed", lambda d: ["modal", T2, "--rpm", "inf"],
         "--rpm must be finite"),
    case("modal-modes-word", "`modal --modes two`", "word for a number", lambda d: ["modal", T2, "--modes", "two"],
         "--modes must be a positive integer"),
    # ---------------------------------------------------------------- campbell
    case("campbell-rpm-letter", "`campbell --rpm 5:1:x`", "letter in the speed range",
         lambda d: ["campbell", T2, "--rpm", "5:1:x"], "--rpm must be A:B:STEP with numbers", how="module"),
    case("campbell-orders-inf", "`campbell --orders 1,2,inf`", "infinite order",
         lambda d: ["campbell", T2, "--rpm", "0:1000:500", "--orders", "1,2,inf"],
         "--orders must be positive and finite"),
    # ---------------------------------------------------------------- simulate
    case("simulate-negative-t-end", "`simulate --t-end -1`", "negative duration",
         lambda d: ["simulate", T2, "--t-end", "-1"], "--t-end must be > 0"),
    case("simulate-dt-above-t-end", "`simulate --t-end 0.01 --dt 0.1`", "step longer than the run",
         lambda d: ["simulate", T2, "--t-end", "0.01", "--dt", "0.1"], "dt: must be > 0 and below t_end"),
    case("simulate-too-many-samples", "`simulate --t-end 1e6`", "output would not fit in memory",
         lambda d: ["simulate", T2, "--t-end", "1e6"], "output samples, at most"),
    case("simulate-rtol-one", "`simulate`: `[simulation] rtol = 1.0`",
         "a tolerance that lets the response go (a damped drive gained energy at rtol = 1)",
         lambda d: ["simulate", write(d, "scene.toml", T200 + "\n[simulation]\nrtol = 1.0\n"), "--t-end", "0.1"],
         "simulation.rtol", "must lie in [1e-14, 0.01]"),
    case("simulate-unknown-solver", "`simulate`: `[simulation] solver = \"euler\"`", "unknown solver",
         lambda d: ["simulate", write(d, "scene.toml", T200 + '\n[simulation]\nsolver = "euler"\n'), "--t-end", "0.1"],
         "simulation.solver: must be one of"),
    case("simulate-rtol-fixed-step", "`simulate`: `rtol = 1e-3` with generalized-alpha (hybrid default)",
         "a tolerance the fixed-step solver does not read",
         lambda d: ["simulate", write(d, "scene.toml", T200 + "\n[simulation]\nrtol = 1e-3\n"), "--t-end", "0.1"],
         "simulation.rtol", "fixed steps"),
    case("simulate-rho-adaptive", "`simulate`: `rho_inf = 0.5` with Dopri8 (rotational default)",
         "a generalized-alpha setting an adaptive solver does not read",
         lambda d: ["simulate", write(d, "scene.toml", FEAD + "\n[simulation]\nrho_inf = 0.5\n"), "--t-end", "0.1"],
         "simulation.rho_inf", "adaptive"),
    case("simulate-settle-leaves-nothing", "`simulate --t-end 0.1 --settle 0.99`", "a summary of one sample",
         lambda d: ["simulate", T2, "--t-end", "0.1", "--settle", "0.99"], "--settle", "fewer than 16"),
    case("out-empty", "`statics scene.toml --out \"\"`", "empty output directory (it wrote into the working one)",
         lambda d: ["statics", T2, "--out", ""], "--out: empty directory name"),
    case("orders-settle-forever", "`orders --method settle --settle-s 1e9`", "a settling transient of 30 years",
         lambda d: ["orders", write(d, "scene.toml", FEAD), "--rpm", "800:800:1", "--method", "settle",
                    "--settle-s", "1e9"], "settle_s", "[0, 100] s"),
    case("simulate-node-out-of-range", "`simulate`: `nodes = [\"crank-alternator:99\"]`", "node beyond the mesh",
         lambda d: ["simulate", write(d, "scene.toml", T200 + '\n[simulation]\nnodes = ["crank-alternator:99"]\n'),
                    "--t-end", "0.1"], "simulation.nodes"),
    case("simulate-torque-window", "`simulate`: torque with `t_end_s` before `t_start_s`", "empty time window",
         lambda d: ["simulate", write(d, "scene.toml", T200 + '\n[[torque]]\npulley = "alternator"\nmean_Nm = 5.0\n'
                                      't_start_s = 2.0\nt_end_s = 1.0\n'), "--t-end", "0.1"],
         "torque[0].t_end_s: must be later than t_start_s"),
    case("simulate-damping-not-enabled", "`simulate`: `CA = 3.0` without `belt_damping`",
         "parameter of an effect that is off",
         lambda d: ["simulate", scene(d, ("rhoA = 0.12101", "rhoA = 0.12101\nCA = 3.0")), "--t-end", "0.1"],
         'belt.CA: given but "belt_damping" is not in model.effects'),
    case("simulate-initial-with-unit", "`simulate`: `rotation_deg = { alternator = \"5 deg\" }`",
         "string for an angle",
         lambda d: ["simulate", write(d, "scene.toml", T200 + '\n[initial]\nrotation_deg = { alternator = "5 deg" }\n'),
                    "--t-end", "0.1"], "initial.rotation_deg.alternator"),
    case("simulate-forcing-above-step-nyquist", "`simulate --dt 2e-4`: a 4990 Hz `[[torque]]`",
         "forcing the step would alias (to 10 Hz)",
         lambda d: ["simulate", write(d, "scene.toml", T200 + '\n[[torque]]\npulley = "alternator"\namplitude_Nm = 5.0\n'
                                      'frequency_hz = 4990.0\n'), "--t-end", "0.1", "--dt", "2e-4"],
         "torque[0].frequency_hz: the torque on alternator at 4990 Hz is at or above the Nyquist frequency 2500 Hz of "
         "the time step dt = 0.0002 s", "false 10 Hz excitation"),
    case("simulate-forcing-above-output-nyquist", "`simulate --output-dt 1e-3`: a 600 Hz `[[span_load]]`",
         "forcing the outputs would alias",
         lambda d: ["simulate", write(d, "scene.toml", T200 + '\n[[span_load]]\nspan = "crank-alternator"\nnode = 8\n'
                                      'amplitude_N = 1.0\nfrequency_hz = 600.0\n'), "--t-end", "0.1",
                    "--output-dt", "1e-3"],
         "span_load[0].frequency_hz", "Nyquist frequency 500 Hz of the output interval", "below 0.0008333 s"),
    case("simulate-unbalance-above-output-nyquist", "`simulate`: the fluctuation scene at `speed_rpm = 30000`",
         "an unbalanced pulley turning faster than the outputs resolve",
         lambda d: ["simulate", write(d, "scene.toml", edit((SCENES / "sim_two_pulley_fluctuation.toml").read_text(),
                                                            ("speed_rpm = 600.0", "speed_rpm = 30000.0"))),
                    "--t-end", "0.1"], "pulley[0].cm_offset: the unbalance of crank"),
    case("simulate-load-window-shorter-than-step", "`simulate --dt 2e-4`: a torque acting for 1e-4 s",
         "a pulse the step can miss",
         lambda d: ["simulate", write(d, "scene.toml", T200 + '\n[[torque]]\npulley = "alternator"\nmean_Nm = 5.0\n'
                                      't_start_s = 0.01\nt_end_s = 0.0101\n'), "--t-end", "0.1", "--dt", "2e-4"],
         "torque[0].t_end_s", "less than 2 time steps"),
    case("simulate-output-dt-below-dt", "`simulate --dt 1e-4 --output-dt 5e-5`", "outputs between the steps",
         lambda d: ["simulate", T2, "--t-end", "0.1", "--dt", "1e-4", "--output-dt", "5e-5"],
         "output_dt: 5e-05 s is below the time step dt = 0.0001 s"),
    case("simulate-too-many-steps", "`simulate --t-end 3000 --output-dt 0.01`", "more steps than the limit",
         lambda d: ["simulate", T2, "--t-end", "3000", "--output-dt", "0.01"],
         "t_end: 3000 s needs 30000000 steps of dt = 0.0001 s, more than the limit of 20000000"),
    # ---------------------------------------------------------------- span
    case("span-too-many-elements", "`span ... --elements 10000`", "mesh too fine",
         lambda d: [*SPAN, "--elements", "10000"], "--elements must be at most 400"),
    case("span-length-1e-300", "`span --length 1e-300 ...`", "a span no mesh can carry",
         lambda d: [*SPAN[:2], "1e-300", *SPAN[3:]], "--length: must lie in [0.0001, 10000] m ("),
    case("span-speed-nan", "`span ... --speed nan`", "NaN speed (it raised a raw LinAlgError)",
         lambda d: [*SPAN, "--speed", "nan"], "--speed: must be finite, got nan"),
    case("span-unknown-bending", "`span ... --bending quadratic`", "unknown choice",
         lambda d: [*SPAN, "--bending", "quadratic"], "argument --bending: invalid choice"),
    case("unknown-command", "`simulat scene.toml`", "misspelt command", lambda d: ["simulat", T2],
         "invalid choice: 'simulat'"),
    # ---------------------------------------------------------------- fit
    case("fit-not-found", "`fit no_such_dataset.toml`", "nonexistent file",
         lambda d: ["fit", str(d / "no_such_dataset.toml")], "dataset file not found"),
    case("fit-directory", "`fit` on a directory", "a directory, not a file", lambda d: ["fit", str(d)],
         "is a directory, not a dataset file"),
    case("fit-malformed-toml", "`fit`: `[torque_angle` (unclosed)", "malformed TOML",
         lambda d: ["fit", dataset(d, '[torque_angle\nfile = "torque_angle.csv"\n')], "malformed TOML"),
    case("fit-empty-dataset", "`fit` on an empty dataset.toml", "nothing to fit",
         lambda d: ["fit", dataset(d, "")], "no section to fit"),
    case("fit-unknown-section", "`fit`: `[tensil]`", "misspelt section",
         lambda d: ["fit", dataset(d, "[tensil]\nspecimen_length_m = 0.1463\n")], "tensil: unknown section"),
    case("fit-empty-csv", "`fit`: empty torque_angle.csv", "empty data file",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv="")], "torque_angle.csv is empty"),
    case("fit-header-only-csv", "`fit`: torque_angle.csv with the header only", "no data rows",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv="angle_deg,torque_Nm\n")],
         "torque_angle.csv has 0 data rows"),
    case("fit-missing-column", "`fit`: torque_angle.csv with `moment_Nm` for `torque_Nm`", "missing column",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE,
                                   torque_angle_csv=edit(TORQUE_ANGLE_CSV, ("torque_Nm", "moment_Nm")))],
         "lacks column(s) torque_Nm"),
    case("fit-nan-in-csv", "`fit`: `nan` in torque_angle.csv", "NaN in the data",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv=edit(TORQUE_ANGLE_CSV, ("75.1026,5.9668",
                                                                                        "75.1026,nan")))],
         "torque_angle.csv line 4: NaN or infinite value"),
    case("fit-huge-in-csv", "`fit`: `5.9668e200` in torque_angle.csv", "a value whose square overflows",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv=edit(TORQUE_ANGLE_CSV, ("75.1026,5.9668",
                                                                                        "75.1026,5.9668e200")))],
         "torque_angle.csv line 4: 5.97e+200 in column 2 (torque_Nm) is beyond +-1e+100"),
    case("fit-unit-in-csv", "`fit`: `5.9668 Nm` in torque_angle.csv", "text in a number cell",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv=edit(TORQUE_ANGLE_CSV, ("75.1026,5.9668",
                                                                                        "75.1026,5.9668 Nm")))],
         "torque_angle.csv line 4: not a number"),
    case("fit-ragged-csv", "`fit`: an impulse CSV row with 3 values", "row longer than the header",
         lambda d: ["fit", dataset(d, IMPULSE, tensioner_arm_csv=edit(IMPULSE_CSV, ("0.0005,56.44382241",
                                                                                 "0.0005,56.44382241,3")))],
         "tensioner_arm.csv line 4: 3 values for 2 columns"),
    case("fit-csv-not-found", "`fit`: `file = \"torque_angel.csv\"`", "data file missing",
         lambda d: ["fit", dataset(d, edit(TORQUE_ANGLE, ("torque_angle.csv", "torque_angel.csv")),
                                   torque_angle_csv=TORQUE_ANGLE_CSV)], "torque_angel.csv", "not found"),
    case("fit-modes-zero", "`fit`: impulse `modes = 0`", "out of range",
         lambda d: ["fit", dataset(d, edit(IMPULSE, ("modes = 2", "modes = 0")), tensioner_arm_csv=IMPULSE_CSV)],
         "impulse.record[0].modes"),
    case("fit-length-with-unit", "`fit`: `specimen_length_m = \"146 mm\"`", "string for a number",
         lambda d: ["fit", dataset(d, edit(TENSILE, ("specimen_length_m = 0.1463", 'specimen_length_m = "146 mm"')))],
         "tensile.specimen_length_m: must be a number"),
    case("fit-frequency-inf", "`fit`: tensile `frequency_hz = inf`", "infinite value",
         lambda d: ["fit", dataset(d, edit(TENSILE, ("frequency_hz = 0.01", "frequency_hz = inf")))],
         "tensile.record[0].frequency_hz: must be finite"),
    case("fit-modal-bad-label", "`fit`: modal `label = \"first transverse\"`", "unreadable mode label",
         lambda d: ["fit", modal_dataset(d, T2, label="first transverse")], "modal.configuration[0].modes[0].label"),
    case("fit-modal-bad-scene", "`fit`: modal configuration whose scene has `EI = nan`", "bad scene inside a dataset",
         lambda d: ["fit", modal_dataset(d, scene(d, ("EI = 0.034", "EI = nan")))],
         "modal.configuration[0].scene", "belt.EI: must be finite"),
    # ---------------------------------------------------------------- sweep
    case("sweep-not-found", "`sweep scene.toml no_such_sweep.toml`", "nonexistent file",
         lambda d: ["sweep", T2, str(d / "no_such_sweep.toml")], "sweep file not found"),
    case("sweep-malformed-toml", "`sweep`: `values = [200, 300` (unclosed)", "malformed TOML",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ("600]", "600")))], "malformed TOML"),
    case("sweep-empty-file", "`sweep` with an empty sweep file", "nothing to sweep",
         lambda d: ["sweep", T2, write(d, "sweep.toml", "")], "grid: no sweep axes"),
    case("sweep-unknown-parameter", "`sweep`: `parameter = \"belt.EJ\"`", "no such parameter",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ('"belt.EI"', '"belt.EJ"')))],
         "grid[1].parameter: belt.EJ"),
    case("sweep-unlisted-effect", "`sweep`: `parameter = \"belt.CA\"` without `belt_damping` in model.effects",
         "a parameter that would change nothing",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ('"belt.EI"', '"belt.CA"')))],
         'grid[1].parameter: belt.CA: belongs to the effect "belt_damping"'),
    case("sweep-negative-tension", "`sweep`: `values = [-200, 300]` for belt.static_tension", "negative tension",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ("[200, 300, 400, 500, 600]", "[-200, 300]")))],
         "grid[0].values: belt.static_tension must be > 0, got -200.0"),
    case("sweep-nan-value", "`sweep`: `values = [200, nan]`", "NaN",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ("[200, 300, 400, 500, 600]", "[200, nan]")))],
         "grid[0].values[1]: must be finite"),
    case("sweep-too-many-cases", "`sweep`: `num = 100000`", "too many cases",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ("num = 4", "num = 100000")))],
         "more than the limit"),
    case("sweep-grid-one-step", "`sweep`: `num = 1` with start != stop", "a range whose stop is dropped",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ("num = 4", "num = 1")))], "num", "never stop"),
    case("sweep-relative-tolerance-percent", "`sweep`: `relative_tolerance = 3` (percent for a fraction)",
         "wrong unit", lambda d: ["sweep", T2, write(d, "sweep.toml", edit(TOLERANCE, ("relative_tolerance = 0.003",
                                                                                    "relative_tolerance = 3")))],
         "random[2].relative_tolerance: must be < 1"),
    case("sweep-no-tensioner", "`sweep`: `tensioner.arm_length` on a drive without tensioner",
         "parameter the scene lacks",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ('"belt.EI"', '"tensioner.arm_length"')))],
         "grid[1].parameter: tensioner.arm_length: the scene has no tensioner"),
    case("sweep-speed-of-a-driven-pulley", "`sweep`: `parameter = \"pulley.alternator.speed_rpm\"`",
         "the speed of a pulley that is not the drive pulley (it changed nothing)",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ('"belt.EI"', '"pulley.alternator.speed_rpm"')))],
         "grid[1].parameter: pulley.alternator.speed_rpm: only the drive pulley takes a speed"),
    case("sweep-EI-1e20", "`sweep`: `belt.EI` from 0.02 to 1e20", "a value no case could use",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ("stop = 0.05", "stop = 1e20")))],
         "grid[1].start: belt.EI must lie in [0, 100000] N m^2"),
    case("sweep-campbell-without-rpm", "`sweep`: `outputs = [\"campbell\"]`, no `rpm`", "missing key",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ('["statics", "modal"]', '["campbell"]')))],
         "rpm: missing"),
    case("sweep-unknown-backend", "`sweep ... --backend spark`", "unknown choice",
         lambda d: ["sweep", T2, write(d, "sweep.toml", SWEEP), "--backend", "spark"],
         "argument --backend: invalid choice"),
    # ---------------------------------------------------------------- optimize
    case("optimize-not-found", "`optimize scene.toml no_such_spec.toml`", "nonexistent file",
         lambda d: ["optimize", TB, str(d / "no_such_spec.toml")], "optimisation file not found"),
    case("optimize-malformed-toml", "`optimize`: `steps = = 150`", "malformed TOML",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("steps = 150", "steps = = 150")))],
         "malformed TOML"),
    case("optimize-steps-zero", "`optimize`: `steps = 0`", "no steps",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("steps = 150", "steps = 0")))],
         "steps: must be >= 1"),
    case("optimize-learning-rate-word", "`optimize`: `learning_rate = \"fast\"`", "string for a number",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("learning_rate = 0.02",
                                                                         'learning_rate = "fast"')))],
         "learning_rate: expected a finite number"),
    case("optimize-bounds-swapped", "`optimize`: `lower = 0.70`, `upper = 0.58`", "empty interval",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("lower = 0.58\nupper = 0.70",
                                                                         "lower = 0.70\nupper = 0.58")))],
         "variable[0].upper: must be > lower"),
    case("optimize-start-outside", "`optimize`: `lower = 0.66` (the scene has 0.64335)", "start outside the bounds",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("lower = 0.58", "lower = 0.66")))],
         "variable[0].parameter", "lies outside [lower, upper]"),
    case("optimize-bound-outside-range", "`optimize`: `lower = -1e200` for tensioner.pivot.x",
         "a bound outside the parameter's accepted range",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("lower = 0.58", "lower = -1e200")))],
         "variable[0].lower: tensioner.pivot.x must lie in [-100000, 100000] m"),
    case("optimize-unknown-parameter", "`optimize`: `parameter = \"tensioner.pivot.z\"`", "no such parameter",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("tensioner.pivot.x", "tensioner.pivot.z")))],
         "variable[0].parameter: tensioner.pivot.z"),
    case("optimize-unknown-kind", "`optimize`: `kind = \"hub_force\"`", "unknown objective",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ('"hub_load"', '"hub_force"')))],
         "objective[1].kind: unknown value 'hub_force'"),
    case("optimize-order-inf", "`optimize`: `orders = [inf]`", "infinite order",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("orders = [2.0]", "orders = [inf]")))],
         "objective[0].orders: expected a non-empty array of positive finite numbers"),
    case("optimize-huge-mesh", "`optimize`: `elements_per_span = 100000`", "mesh that cannot fit in memory",
         lambda d: ["optimize", TB, write(d, "opt.toml", "elements_per_span = 100000\n" + OPTIMIZE)],
         "elements_per_span: must be <= 400"),
    case("optimize-arm-without-tensioner", "`optimize`: `arm_angle_deg` constraint on the two-pulley drive",
         "constraint the scene cannot have",
         lambda d: ["optimize", T2, write(d, "opt.toml", '[[variable]]\nparameter = "pulley.alternator.center.x"\n'
                                          'lower = 0.2\nupper = 0.3\n\n[[objective]]\nkind = "hub_load"\n'
                                          'pulley = "alternator"\n\n[[constraint]]\nkind = "arm_angle_deg"\n'
                                          'min = 30\n')],
         "constraint[0].kind: the scene has no tensioner"),
    case("optimize-weights-zero", "`optimize`: every objective's `weight = 0.0`", "nothing to minimise (it moved the "
         "layout and said \"goal met\")",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("weight = 1.0", "weight = 0.0"),
                                                              ("weight = 0.001", "weight = 0.0")))],
         "objective[0].weight", "nothing to minimise"),
    case("optimize-starts-zero", "`optimize`: `starts = 0`", "no start",
         lambda d: ["optimize", TB, write(d, "opt.toml", "starts = 0\n" + OPTIMIZE)], "starts: must be >= 1, got 0"),
    case("optimize-tolerance-hz-negative", "`optimize`: `tolerance_hz = -0.1`", "negative resonance tolerance",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("margin_hz = 2.0", "margin_hz = 2.0\n"
                                                                                           "tolerance_hz = -0.1")))],
         "objective[0].tolerance_hz: must be >= 0"),
    # ---------------------------------------------------------------- input files: regular, bounded, UTF-8
    case("scene-named-pipe", "`statics pipe.toml` (a named pipe)", "not a regular file (reading would block)",
         lambda d: ["statics", fifo(d, "pipe.toml")], "pipe.toml: is a named pipe, not a regular file"),
    case("sweep-named-pipe", "`sweep scene.toml pipe.toml` (a named pipe)", "not a regular file",
         lambda d: ["sweep", T2, fifo(d, "pipe.toml")], "pipe.toml: is a named pipe"),
    case("optimize-named-pipe", "`optimize scene.toml pipe.toml` (a named pipe)", "not a regular file",
         lambda d: ["optimize", TB, fifo(d, "pipe.toml")], "pipe.toml: is a named pipe"),
    case("fit-named-pipe", "`fit pipe.toml` (a named pipe)", "not a regular file",
         lambda d: ["fit", fifo(d, "pipe.toml")], "pipe.toml: is a named pipe"),
    case("fit-csv-named-pipe", "`fit`: torque_angle.csv is a named pipe", "data file not a regular file",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE), fifo(d / "data", "torque_angle.csv")][:2],
         "torque_angle", "torque_angle.csv: is a named pipe"),
    case("scene-dev-zero", "`statics /dev/zero`", "a device (endless)", lambda d: ["statics", "/dev/zero"],
         "/dev/zero: is a device, not a regular file"),
    case("fit-dev-zero", "`fit /dev/zero`", "a device (endless)", lambda d: ["fit", "/dev/zero"],
         "/dev/zero: is a device"),
    case("scene-too-large", "`statics` on a 9 MiB scene file", "over the size limit (8 MiB)",
         lambda d: ["statics", sparse(d, "big.toml", 9 * MIB)], "big.toml: 9.0 MiB, more than the limit of 8.0 MiB"),
    case("fit-csv-too-large", "`fit`: a 65 MiB torque_angle.csv", "data file over the size limit (64 MiB)",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE), sparse(d / "data", "torque_angle.csv", 65 * MIB)][:2],
         "torque_angle.csv: 65.0 MiB, more than the limit of 64.0 MiB"),
    case("scene-bom-then-nan", "`statics`: a scene with a UTF-8 byte-order mark and `EI = nan`",
         "the mark is accepted: the error is the NaN",
         lambda d: ["statics", write(d, "scene.toml", b"\xef\xbb\xbf" + edit(T200, ("EI = 0.034", "EI = nan")).encode())],
         "belt.EI: must be finite"),
    case("fit-csv-bom-then-nan", "`fit`: torque_angle.csv with a byte-order mark and `nan` on line 4",
         "the mark is accepted: the error is the NaN",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv=b"\xef\xbb\xbf" + edit(
             TORQUE_ANGLE_CSV, ("75.1026,5.9668", "75.1026,nan")).encode())],
         "torque_angle.csv line 4: NaN or infinite value"),
    case("fit-csv-not-utf8", "`fit`: torque_angle.csv of binary bytes", "not a text file",
         lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv=b"angle_deg,torque_Nm\n\xff\xfe" + PLANTED.encode())],
         "torque_angle.csv: not a UTF-8 text file", "line 2, column 1"),
    # ---------------------------------------------------------------- datasets name files inside their folder
    case("fit-csv-parent", "`fit`: `file = \"../torque_angle.csv\"`", "a file outside the dataset's folder",
         lambda d: ["fit", torque_angle_named(d, "../torque_angle.csv")],
         "torque_angle.file: '../torque_angle.csv' leads out of the dataset's folder"),
    case("fit-csv-absolute", "`fit`: `file = \"/etc/passwd\"`", "an absolute path",
         lambda d: ["fit", torque_angle_named(d, "/etc/passwd")], "torque_angle.file: '/etc/passwd' is an absolute path"),
    case("fit-csv-link-out", "`fit`: torque_angle.csv a link to ../torque_angle.csv", "a link out of the folder",
         lambda d: ["fit", torque_angle_named(d, "torque_angle.csv"),
                    link(d / "data", "torque_angle.csv", d / "torque_angle.csv")][:2],
         "torque_angle.file: 'torque_angle.csv' is a link to a file outside the dataset's folder"),
    case("fit-modal-scene-parent", "`fit`: modal `scene = \"../scene.toml\"`", "a scene outside the folder",
         lambda d: ["fit", write(d, "scene.toml", T200) and dataset(
             d, '[modal]\nparameters = ["belt.EI"]\n[[modal.configuration]]\nscene = "../scene.toml"\n'
                'modes = [{ label = "1st transverse", frequency_hz = 30.0 }]\n')],
         "modal.configuration[0].scene: '../scene.toml' leads out of the dataset's folder"),
    # ---------------------------------------------------------------- values no key can carry
    case("scene-400-digit-integer", "`statics`: `EI = 99...9` (400 digits)", "integer beyond 64 bits",
         lambda d: ["statics", scene(d, ("EI = 0.034", "EI = " + "9" * 400))],
         "belt.EI: an integer of 400 digits"),
    case("optimize-400-digit-integer", "`optimize`: `steps = 10^400`", "integer beyond 64 bits",
         lambda d: ["optimize", TB, write(d, "opt.toml", edit(OPTIMIZE, ("steps = 150", "steps = 1" + "0" * 400)))],
         "steps: an integer of 401 digits"),
    case("scene-5000-digit-number", "`statics`: `EI = 99...9` (5000 digits)", "a number Python cannot read",
         lambda d: ["statics", scene(d, ("EI = 0.034", "EI = " + "9" * 5000))],
         "belt.EI: a value written with 5000 characters"),
    case("scene-deep-array", "`statics`: `EI = [[[...]]]` nested 100000 deep", "nesting no parser recursion takes",
         lambda d: ["statics", scene(d, ("EI = 0.034", "EI = " + "[" * 100000 + "]" * 100000))],
         "belt.EI: arrays or inline tables nested more than 20 deep"),
    case("fit-deep-inline-table", "`fit`: `angle_offset_deg = {a={a=...}}` nested 100000 deep", "deep nesting",
         lambda d: ["fit", dataset(d, edit(TORQUE_ANGLE, ("[torque_angle]", "[torque_angle]\nangle_offset_deg = "
                                                          + "{a=" * 100000 + "1" + "}" * 100000)),
                                   torque_angle_csv=TORQUE_ANGLE_CSV)],
         "torque_angle.angle_offset_deg: arrays or inline tables nested more than 20 deep"),
    case("sweep-deep-tables", "`sweep`: `[x.a. ... .a]` 15 deep, `b.b. ... .b = 1` 10 more", "tables nested too deep",
         lambda d: ["sweep", T2, write(d, "sweep.toml", SWEEP + "\n[grid_x" + ".a" * 14 + "]\nb" + ".b" * 9 + " = 1\n")],
         "grid_x.a.a.a", "nested more than 20 deep"),
    case("scene-dotted-key", "`statics`: `a.a.a. ... .a = 1` (100000 parts)", "a key tomllib reads in quadratic time",
         lambda d: ["statics", write(d, "scene.toml", "a" + ".a" * 100000 + " = 1\n" + T200)],
         "a.a.a.a", "a dotted key of more than 20 parts (line 1)"),
    case("sweep-megabyte-description", "`sweep`: a description of 2 MB", "string over its limit (10000 characters)",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ('description = "', 'description = "' + "x" * 2_000_000)))],
         "description: a string of 2000", "longer than the limit of 10000"),
    case("scene-long-name", "`statics`: a pulley name of 1000 characters", "name over its limit (100 characters)",
         lambda d: ["statics", scene(d, ('name = "crank"', 'name = "' + "c" * 1000 + '"'))],
         "pulley[0].name: a string of 1000 characters, longer than the limit of 100"),
    case("sweep-huge-array", "`sweep`: `values` with 200000 elements", "array over its limit (100000)",
         lambda d: ["sweep", T2, write(d, "sweep.toml", edit(SWEEP, ("[200, 300, 400, 500, 600]",
                                                                     "[" + "200," * 200000 + "]")))],
         "grid[0].values: an array of 200000 elements"),
    # ---------------------------------------------------------------- two things with one name
    case("fit-modal-duplicate-name", "`fit`: two modal configurations named `T200`",
         "one fitted belt length would overwrite the other",
         lambda d: ["fit", two_configurations(d)],
         "modal.configuration[1].name: configuration name 'T200' is also that of modal.configuration[0]"),
    case("fit-impulse-duplicate-name", "`fit`: two impulse records named `tensioner arm`",
         "one record's plot would overwrite the other's",
         lambda d: ["fit", dataset(d, IMPULSE + IMPULSE[IMPULSE.index("[[impulse.record]]"):],
                                   tensioner_arm_csv=IMPULSE_CSV)],
         "impulse.record[1].name: record name 'tensioner arm' is taken by impulse.record[0]"),
    case("fit-modal-length-and-tension", "`fit`: modal `parameters = [\"belt.length\", \"belt.static_tension\"]`",
         "setting one belt key overwrites the other",
         lambda d: ["fit", two_configurations(d, "T200b", '["belt.length", "belt.static_tension"]')],
         "modal.parameters: lists both belt.length and belt.static_tension"),
]


def _run(c: Case, tmp_path: pathlib.Path, capsys) -> tuple[int, str, pathlib.Path]:
    """Run a row: (exit status, stderr, output directory)."""
    out = tmp_path / "out"
    argv = c.argv(tmp_path)
    if "--out" not in argv:
        argv = [*argv, "--out", str(out)]
    if c.how == "main":
        code = _with_timeout(lambda: main(argv), ROW_TIMEOUT_S)
        return code, capsys.readouterr().err, out
    env = {k: v for k, v in os.environ.items() if k != "BELTJAX_DEBUG"}
    if c.how == "script":
        exe = shutil.which("beltjax") or str(pathlib.Path(sys.executable).parent / "beltjax")
        cmd = [exe, *argv]
    else:
        cmd = [sys.executable, "-m", "beltjax.cli", *argv]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    return proc.returncode, proc.stderr, out


ROW_TIMEOUT_S = 120  # an in-process row that blocks (a named pipe opened for reading) fails, never hangs


def _with_timeout(fn, seconds):
    """``fn()``, failed by an alarm after ``seconds`` (where the platform has SIGALRM)."""
    if not hasattr(signal, "SIGALRM"):
        return fn()

    def alarm(*_):
        raise TimeoutError(f"no answer after {seconds} s (blocked?)")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(seconds)
    try:
        return fn()
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(autouse=True)
def _compile_cache(tmp_path_factory, monkeypatch):
    """The commands' persistent JAX cache goes to a temporary folder, not the user's home."""
    monkeypatch.setenv("BELTJAX_CACHE", str(tmp_path_factory.getbasetemp() / "jax_cache"))
    monkeypatch.delenv("BELTJAX_DEBUG", raising=False)


@pytest.mark.parametrize("c", CASES, ids=[c.id for c in CASES])
def test_bad_input_gives_one_line_error(c: Case, tmp_path, capsys):
    code, err, out = _run(c, tmp_path, capsys)
    lines = err.rstrip("\n").split("\n")
    assert code == 2, f"exit status {code}, stderr: {err}"
    assert len(lines) == 1 and lines[0].strip(), f"expected one line on stderr, got: {err!r}"
    line = lines[0]
    assert line.startswith(PREFIX), line
    assert "Traceback" not in err
    for text in c.expect:
        assert text in line, f"{text!r} not in {line!r}"
    written = [p for p in out.rglob("*") if p.is_file()] if out.is_dir() else []
    assert not written, f"result files written for bad input: {written}"


def test_the_table_is_broad_and_fast(tmp_path):
    """At least 30 rows, every command covered, at most MAX_COMPILING rows that compile."""
    assert len(CASES) >= 30
    assert len({c.id for c in CASES}) == len(CASES)
    first = {c.argv(tmp_path / c.id)[0] for c in CASES}
    assert {"statics", "modal", "campbell", "simulate", "span", "fit", "sweep", "optimize"} <= first
    assert sum(c.compiles for c in CASES) <= MAX_COMPILING
    assert {c.how for c in CASES} == {"main", "script", "module"}


# Files whose contents hold PLANTED where an error is found: the message names the file, key, line
# and column, never the text.
PLANTED_FILES = [
    ("scene-malformed-line", lambda d: ["statics", scene(d, ("EA = 111190.0", f"EA = 111190.0 {PLANTED}"))]),
    ("scene-illegal-character", lambda d: ["statics", scene(d, ("EA = 111190.0", f'EA = "{PLANTED}\x01"'))]),
    ("scene-not-utf8", lambda d: ["statics", write(d, "s.toml", f"# {PLANTED}\n".encode() + b"\xff" + PLANTED.encode())]),
    ("scene-inline-duplicate", lambda d: ["statics", scene(d, ("EA = 111190.0", f"EA = {{ {PLANTED} = 1, {PLANTED} = 2 }}"))]),
    ("sweep-malformed", lambda d: ["sweep", T2, write(d, "sweep.toml", f"[grid\n{PLANTED}\n")]),
    ("fit-csv-header", lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv=edit(
        TORQUE_ANGLE_CSV, ("torque_Nm", PLANTED)))]),
    ("fit-csv-cell", lambda d: ["fit", dataset(d, TORQUE_ANGLE, torque_angle_csv=edit(
        TORQUE_ANGLE_CSV, ("75.1026,5.9668", f"75.1026,5.9668 {PLANTED}")))]),
    ("fit-csv-is-a-scene", lambda d: ["fit", write(d / "data", "scene.toml", f'description = "{PLANTED}"\n' + T200)
                                      and dataset(d, edit(TORQUE_ANGLE, ("torque_angle.csv", "scene.toml")))]),
    ("fit-csv-outside", lambda d: ["fit", torque_angle_named(d, "../torque_angle.csv")]),
    ("fit-modal-scene-malformed", lambda d: ["fit", write(d / "data", "scene.toml", f"[belt\n{PLANTED}\n") and dataset(
        d, '[modal]\nparameters = ["belt.EI"]\n[[modal.configuration]]\nscene = "scene.toml"\n'
           'modes = [{ label = "1st transverse", frequency_hz = 30.0 }]\n')]),
]


@pytest.mark.parametrize("argv", [a for _, a in PLANTED_FILES], ids=[i for i, _ in PLANTED_FILES])
def test_no_message_quotes_a_file(argv, tmp_path, capsys):
    c = Case("planted", "", "", argv, ())
    code, err, _ = _run(c, tmp_path, capsys)
    assert code == 2 and err.count("\n") == 1 and err.startswith(PREFIX), err
    assert PLANTED not in err and "PLANTED" not in err, err


def test_byte_order_mark_is_accepted(tmp_path):
    """A scene and a CSV file with a UTF-8 byte-order mark read exactly as without it."""
    from beltjax.scene import load_scene
    from identification.data import read_csv

    plain, marked = write(tmp_path, "plain.toml", T200), write(tmp_path, "bom.toml", b"\xef\xbb\xbf" + T200.encode())
    assert repr(load_scene(marked)).replace(marked, "") == repr(load_scene(plain)).replace(plain, "")
    cols = ["angle_deg", "torque_Nm"]
    a = read_csv(pathlib.Path(write(tmp_path, "a.csv", TORQUE_ANGLE_CSV)), cols, "k")
    b = read_csv(pathlib.Path(write(tmp_path, "b.csv", b"\xef\xbb\xbf" + TORQUE_ANGLE_CSV.encode())), cols, "k")
    assert all((a[k] == b[k]).all() and a[k].size > 10 for k in cols)
