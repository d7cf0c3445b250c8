"""The running belt's compatibility on three drives: how closely each operating point's spans and
arcs hold the installed belt, with ``belt_slip`` listed (a belt that creeps: the running belt's
compatibility) and without (a belt that grips every rim: the arcs kept as installed), what it
moves, and Shigley's Example 17-1 installed so that it runs at the book's mean.

Usage::

    python benchmarks/running_belt_length.py       # about 1 min

Not a timing: the numbers the README quotes in "The running belt's length" and in Shigley's
check.  The belt held is written out by quadrature of the creep profile (tests/_creep_profile.py,
the tests' reference), apart from the model's first-order formula.  Writes
results/running_belt_length.json.
"""

from __future__ import annotations

import sys

from _common import HERE, save_json, table

import numpy as np  # noqa: E402

from beltjax import parameters, statics  # noqa: E402
from beltjax.scene import load_scene, loads_scene  # noqa: E402

sys.path.insert(0, str(HERE.parent / "tests"))
from _creep_profile import belt_held, creeping, gripping  # noqa: E402
from _scenes import loaded_two_pulley  # noqa: E402

SCENES = HERE.parent / "scenes"
LBF = 4.4482216152605


def _text(name: str) -> str:
    """The scene text of ``name``; "two_pulley": the two-pulley bench at 800 rpm with 6 N m on
    the alternator and mu = 0.4 (tests/_scenes.py, as tests/test_operating_point.py)."""
    if name != "two_pulley":
        return (SCENES / name).read_text()
    return loaded_two_pulley("rotational", 6.0, "friction_coefficient = 0.4")


def main():
    names = {"two_pulley": "two-pulley bench, 6 N m", "fead_8pulley.toml": "eight-pulley drive",
             "shigley_flat_belt.toml": "Shigley Example 17-1"}
    rows, records = [], []
    for key, name in names.items():
        grip, creep = loads_scene(gripping(_text(key))), loads_scene(creeping(_text(key)))
        r0, r = statics.analyse_statics(grip), statics.analyse_statics(creep)
        L = float(r.inst.belt_length)
        e_creep, e_grip = belt_held(creep, r) / L - 1, belt_held(grip, r0) / L - 1
        dT = np.asarray(r.span_tensions_N) - np.asarray(r0.span_tensions_N)
        arm = None if grip.tensioner is None else r.tensioner_angle_deg - r0.tensioner_angle_deg
        rows.append([name, f"{e_creep:+.2e}", f"{e_grip:+.2e}", f"{dT.min():+.2f} to {dT.max():+.2f}",
                     "-" if arm is None else f"{arm:+.3f}", f"{1e3 * np.max(np.abs(r.inst.creep)):.3f}"])
        records.append(dict(drive=name, held_error=e_creep, grip_held_error=e_grip, tension_change_N=dT,
                            arm_change_deg=arm, creep_m=np.asarray(r.inst.creep), tensions_N=r.span_tensions_N,
                            grip_tensions_N=r0.span_tensions_N, unloaded_tensions_N=r.unloaded["span_tensions_N"]))
    print(table(["drive (operating point)", "belt held / installed - 1", "gripping belt's", "tensions moved [N]",
                 "arm moved [deg]", "max belt moved [mm]"], rows,
                title="The running belt's compatibility (belt_slip) against a belt that grips "
                      "(quadrature of the creep profile)") + "\n")

    sc = load_scene(SCENES / "shigley_flat_belt.toml")  # belt_slip listed
    slack, tight = np.asarray(records[2]["tensions_N"]) / LBF
    delta = tight - 420.0
    r = statics.analyse_statics(parameters.set_value(sc, "belt.static_tension", sc.belt.static_tension - delta * LBF))
    s2, t2 = np.asarray(r.span_tensions_N) / LBF
    f2 = r.friction["driver"]["friction_needed"]
    print(f"Shigley: installed at F_i + F_c = {float(sc.belt.static_tension) / LBF:.1f} lbf the drive runs at "
          f"F_1 / F_2 = {tight:.1f} / {slack:.1f} lbf (both {delta:.2f} lbf above the book's); installed "
          f"{delta:.2f} lbf ({delta * LBF:.1f} N) lower, at {t2:.2f} / {s2:.2f} lbf with f' = {f2:.4f}")
    save_json("running_belt_length", dict(drives=records,
                                          shigley=dict(delta_lbf=delta, F1_lbf=t2, F2_lbf=s2, friction_needed=f2)))


if __name__ == "__main__":
    main()
