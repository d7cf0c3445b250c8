"""Predict the tensioner bench's other spring stages with the arm identified at stage 2.

Usage (after ``beltjax fit identification/examples/tensioner_modal/dataset.toml --out out/fit_tensioner``)::

    python identification/examples/predict_tensioner_stages.py out/fit_tensioner/fit.json

The modal fit of stage 2 (Table 7.9) gives the belt's effective length, the spring preload and
the arm's centre-of-mass distance.  The thesis' three stages differ only in the spring's
preload angle (67.8, 94.5 and 118.3 deg: ``bench.tensioner.spring_preload_angles_deg``), so each
stage here is the fitted scene with the preload moved by the same difference.  Printed per
stage: the arm angle (deg), the tension (N), the alternator's bearing force (N), the spring
moment on the arm (N m) beside the printed spring's k (theta_0 - theta) there, the 1st and 2nd
rotational modes and the upper span's 1st transverse mode (Hz).  Only stage 2 was measured (the thesis prints no spectrum of
stages 1 and 3): the other rows are predictions, to check on the bench.
"""

from __future__ import annotations

import json
import math
import pathlib
import sys

import beltjax

REPO = pathlib.Path(__file__).resolve().parents[2]
REFERENCE = REPO.parent / "shared" / "reference" / "thesis_reference.json"


def main(argv: list[str]) -> int:
    beltjax.configure()
    from beltjax import drive_modal, parameters
    from beltjax.scene import load_scene

    fit = json.loads(pathlib.Path(argv[0]).read_text())["modal"]["parameters"]
    values = {k: v["value"] for k, v in fit.items()}
    stages = json.loads(REFERENCE.read_text())["bench"]["tensioner"]["spring_preload_angles_deg"]
    scene = load_scene(REPO / "identification" / "examples" / "tensioner_modal" / "tensioner_bench_stage2.toml")
    shift = values["tensioner.spring_preload_deg"] - float(scene.tensioner.spring_preload_deg)
    print(f"arm centre of mass {values['tensioner.arm_cm_distance']:.4f} m from the pivot; belt length "
          f"{values['belt.length']:.5f} m; preload {shift:+.2f} deg from the printed stages")
    print(f"{'stage':>5} {'preload':>8} {'arm deg':>8} {'T N':>7} {'|F_alt| N':>9} {'M N m':>6} {'printed':>7} "
          f"{'1st rot. Hz':>11} {'2nd rot. Hz':>11} {'T1 1st Hz':>9}")
    for k, stage in enumerate(stages, start=1):
        sc = parameters.set_values(scene, {**values, "tensioner.spring_preload_deg": stage + shift})
        res = drive_modal.analyse_modes(sc)
        f = dict(zip(res.labels, res.frequencies_hz))
        rot = [x for lab, x in zip(res.labels, res.frequencies_hz) if "rotational" in lab]
        st = res.statics
        t = scene.tensioner
        printed = float(t.spring_stiffness) * math.radians(stage - st.tensioner_angle_deg)
        F = math.hypot(*st.hub_forces_N["alternator"])
        print(f"{k:>5} {stage + shift:>8.2f} {st.tensioner_angle_deg:>8.2f} {float(st.span_tensions_N[0]):>7.1f} "
              f"{F:>9.1f} {st.spring_moment_Nm:>6.2f} {printed:>7.2f} {rot[0]:>11.2f} {rot[1]:>11.2f} {f.get('1st transverse alternator-crank', float('nan')):>9.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
