"""Write the bench modal-fit datasets from the thesis' *measured* natural frequencies.

Not synthesised: the frequencies are the bench measurements printed in the thesis (Silveira
2015), read from ../shared/reference/thesis_reference.json:

* ``bench_modal/``: the two-pulley bench at T = 200, 400 and 600 N (Tables 7.2, 7.4, 7.6;
  "experiment" column; modes without a measurement are left out).  Fitted: EI (one value) and
  the unstretched belt length of each configuration (the installation tension was set by
  moving the alternator, so each configuration has its own effective length).
* ``tensioner_modal/``: the tensioner bench at spring preload stage 2 (Table 7.9, "experiment"
  column: its 13 transverse modes in the three spans and its two rotational modes).  Fitted: the
  unstretched belt length and the spring preload angle, i.e. the belt's effective length on
  this bench and the spring moment that holds it (the arm angle and the tension then follow),
  and the distance of the arm's centre of mass from the pivot (the thesis' x_cm1, not printed),
  which the rotational modes see through the arm's inertia about the pivot.

Each dataset folder holds copies of the scenes it fits (a dataset names only files inside its own
folder); tests/test_identification_modal.py checks that they equal the files in ``scenes/``.

Run from the repository root: ``python identification/examples/make_bench_modal.py``.
"""

import json
import pathlib
import shutil

HERE = pathlib.Path(__file__).resolve().parent
REPO = HERE.parents[1]
REFERENCE = REPO.parent / "shared" / "reference" / "thesis_reference.json"
SCENES = REPO / "scenes"


def _scene_copy(out: pathlib.Path, name: str) -> str:
    """Copy scenes/<name> into the dataset folder ``out``; the dataset's line naming it."""
    shutil.copyfile(SCENES / name, out / name)
    return f'scene = "{name}"   # a copy of scenes/{name}'


def _mode_line(label: str, f: float, span: str | None = None) -> str:
    where = f' span = "{span}",' if span else ""
    return f'  {{ label = "{label}",{where} frequency_hz = {f} }},'


def main() -> None:
    ref = json.loads(REFERENCE.read_text())
    cases = ref["two_pulley_bench"]["modal"]["cases"]
    out = HERE / "bench_modal"
    out.mkdir(exist_ok=True)
    lines = [
        "# Modal fit of the thesis' two-pulley bench: measured frequencies of Tables 7.2, 7.4, 7.6",
        "# (written by make_bench_modal.py from ../shared/reference/thesis_reference.json;",
        "# measured on the bench, not synthesised).  beltjax fit identification/examples/bench_modal/dataset.toml",
        "[modal]",
        'parameters = ["belt.EI", "belt.length"]',
        'per_configuration = ["belt.length"]   # each tension was set by moving the alternator',
        "",
    ]
    for c in cases:
        T = int(c["T"])
        lines += [
            "[[modal.configuration]]",
            f'name = "T{T}"',
            _scene_copy(out, f"two_pulley_T{T}.toml") + f' (X_A = {c["X_A"]} m)',
            "modes = [",
        ]
        lines += [_mode_line(shape, f_exp) for _, _, f_exp, shape in c["modes"] if f_exp is not None]
        lines += ["]", ""]
    (out / "dataset.toml").write_text("\n".join(lines))
    print(f"wrote {out / 'dataset.toml'}")
    _tensioner(ref)


#: the thesis' span names (reference "spans") -> this model's span names (route order)
_SPANS = {"T1": "alternator-crank", "T2": "crank-tensioner", "T3": "tensioner-alternator"}


def _tensioner(ref) -> None:
    stage2 = ref["tensioner_bench_stage2"]
    out = HERE / "tensioner_modal"
    out.mkdir(exist_ok=True)
    lines = [
        "# Modal fit of the thesis' tensioner bench, spring preload stage 2: the measured transverse",
        "# and rotational frequencies of Table 7.9 (written by make_bench_modal.py from",
        "# ../shared/reference/thesis_reference.json; measured on the bench, not synthesised).",
        "# The rotational modes move the arm: they identify its centre of mass (not printed).",
        "#   beltjax fit identification/examples/tensioner_modal/dataset.toml",
        "[modal]",
        'parameters = ["belt.length", "tensioner.spring_preload_deg", "tensioner.arm_cm_distance"]',
        "",
        "[[modal.configuration]]",
        'name = "stage2"',
        _scene_copy(out, "tensioner_bench_stage2.toml"),
        "modes = [",
    ]
    for _, _, f_exp, shape in stage2["modal"]["modes"]:
        label, _, span = shape.partition(" (")
        if f_exp is None or not ("transverse" in label or "rotational" in label):
            continue
        where = _SPANS[span.rstrip(")")] if "transverse" in label else None  # a rotational mode: no span
        lines.append(_mode_line(label, f_exp, where))
    lines += ["]", ""]
    (out / "dataset.toml").write_text("\n".join(lines))
    print(f"wrote {out / 'dataset.toml'}")


if __name__ == "__main__":
    main()
