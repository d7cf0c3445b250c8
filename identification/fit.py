"""``beltjax fit DATA.toml``: read a dataset, fit each of its sections, write the results.

A dataset (TOML; CSV paths relative to it) holds any of these sections, each fitted by its
own module:

=================  =======================================  ======================================
section            data                                     fitted
=================  =======================================  ======================================
``[tensile]``      sinusoidal tensile records               complex modulus G(f), EA(f), DA(f)
``[torque_angle]`` tensioner torque-angle loop              spring stiffness, free angle, friction
``[impulse]``      decaying responses                       modal frequencies and damping ratios
``[modal]``        measured natural frequencies + scenes    any scene parameters (EI, length, ...)
=================  =======================================  ======================================

Writes ``fit.json`` ({section: results}), ``fitted_parameters.toml`` (blocks to paste into a
scene) and each section's plots into the output folder.
"""

from __future__ import annotations

import pathlib

from beltjax import textfile
from beltjax import outputs
from identification.data import DataError


def _fitters():
    from identification import damping, modal_fit, tensile, torque_angle

    return {
        "tensile": tensile.fit_tensile,
        "torque_angle": torque_angle.fit_torque_angle,
        "impulse": damping.fit_impulse,
        "modal": modal_fit.fit_modal,
    }


SECTIONS = ("tensile", "torque_angle", "impulse", "modal")


def load(path: pathlib.Path) -> dict:
    """The dataset's TOML tables; :class:`DataError` for a missing file, one that is not a regular
    file of bounded size, malformed TOML or values no key can carry (see :mod:`beltjax.textfile`)."""
    def fail(key, message):
        raise DataError(message, key)

    path = pathlib.Path(textfile.file_name(path, "dataset", fail))
    data = textfile.load_toml(path, "dataset", textfile.keyed(fail))
    unknown = [k for k in data if k not in SECTIONS]
    if unknown:
        raise DataError(f"unknown section in {path.name} (known: {', '.join(SECTIONS)})", unknown[0])
    if not data:
        raise DataError(f"{path}: no section to fit (add one of {', '.join(SECTIONS)})", "")
    return data


def fit_dataset(path: pathlib.Path) -> dict:
    """Fit every section of the dataset at ``path``: {section: result object}."""
    data = load(path)
    path = pathlib.Path(path)
    fitters = _fitters()
    return {name: fitters[name](data[name], path.parent, name) for name in SECTIONS if name in data}


def run(path: pathlib.Path, out: pathlib.Path) -> int:
    """Command ``beltjax fit``: fit, print the tables, write fit.json, the scene blocks and plots."""
    path = pathlib.Path(path)
    print(f"fitting {path}", flush=True)
    results = fit_dataset(path)
    report, blocks, files = {"dataset": str(path)}, [], []
    for name, res in results.items():
        print(f"\n[{name}]")
        print(res.table())
        report[name] = res.to_json()
        blocks.append(f"# ---- from [{name}] of {path.name}\n{res.scene_block()}")
        files += res.plot(out)
    outputs.write_json(out / "fit.json", report)
    (out / "fitted_parameters.toml").write_text("\n\n".join(blocks) + "\n")

    print()
    outputs.wrote([out / "fit.json", out / "fitted_parameters.toml", *files])
    return 0
