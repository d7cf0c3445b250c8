"""The `beltjax statics|modal|campbell` commands: outputs, figures, one-line errors.

Run in-process through ``beltjax.cli.main`` so that the compiled functions are
shared with the other drive tests.
"""

import json
import pathlib

import numpy as np
import pytest

from beltjax.cli import main

SCENES = pathlib.Path(__file__).resolve().parents[1] / "scenes"
T200 = str(SCENES / "two_pulley_T200.toml")


def _one_line_error(capsys, argv, needle):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code != 0
    assert len(err.splitlines()) == 1, err
    assert needle in err, err
    return err


def test_statics_command(tmp_path, capsys):
    assert main(["statics", T200, "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "alternator" in out and "statics.json" in out
    d = json.loads((tmp_path / "statics.json").read_text())
    np.testing.assert_allclose(d["span_tensions_N"], 200.0, rtol=1e-6)
    assert len(d["span_tensions_N"]) == 2 and set(d["hub_forces_N"]) == {"crank", "alternator"}
    assert 1.79 < d["belt_length_m"] < 1.80
    assert (tmp_path / "layout.png").stat().st_size > 10_000


def test_modal_command(tmp_path, capsys):
    assert main(["modal", T200, "--modes", "12", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1st rotational" in out
    d = json.loads((tmp_path / "modal.json").read_text())
    f = d["frequencies_hz"]
    assert len(f) == len(d["labels"]) == 12
    assert f == sorted(f) and f[0] == 0.0 and d["labels"][0] == "rigid body"
    assert abs(f[1] - 30.2) < 0.3
    assert (tmp_path / "modes.png").stat().st_size > 10_000


def test_campbell_command(tmp_path, capsys):
    argv = ["campbell", T200, "--rpm", "0:2000:500", "--modes", "6", "--orders", "1,2", "--out", str(tmp_path)]
    assert main(argv) == 0
    cap = capsys.readouterr()
    assert "crossings" in cap.out and "speeds" in cap.err  # progress on stderr
    d = json.loads((tmp_path / "campbell.json").read_text())
    assert d["rpm"] == [0.0, 500.0, 1000.0, 1500.0, 2000.0]
    assert np.shape(d["frequencies_hz"]) == (5, 6) and len(d["labels"]) == 6
    assert d["orders"] == [1.0, 2.0] and d["transport_effect"] is True
    f = np.array(d["frequencies_hz"])
    assert np.all(np.diff(f[:, 1]) < 0)  # transverse frequencies fall with speed
    for c in d["crossings"]:
        assert abs(c["frequency_hz"] - c["order"] * c["rpm"] / 60) < 1e-9
    assert (tmp_path / "campbell.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["campbell", T200, "--rpm", "0:100"], "--rpm"),
        (["campbell", T200, "--rpm", "100:0:10"], "--rpm"),
        (["campbell", T200, "--rpm", "0:100:0"], "--rpm"),
        (["campbell", T200, "--rpm", "a:b:c"], "--rpm"),
        (["campbell", T200, "--rpm", "0:100000:1"], "--rpm"),
        (["campbell", T200, "--rpm", "0:100:10", "--orders", "-1,2"], "--orders"),
        (["campbell", T200, "--rpm", "0:100:10", "--modes", "0"], "--modes"),
        (["modal", T200, "--modes", "x"], "--modes"),
        (["statics", "no/such/scene.toml"], "no/such/scene.toml"),
        (["campbell", T200], "--rpm"),
    ],
)
def test_bad_arguments(argv, needle, capsys, tmp_path):
    _one_line_error(capsys, argv + ["--out", str(tmp_path)], needle)


def test_bad_scene_and_bad_belt(tmp_path, capsys):
    text = pathlib.Path(T200).read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("[belt]", "[belt]\ncolour = 'black'"))
    _one_line_error(capsys, ["statics", str(bad), "--out", str(tmp_path)], "belt.colour")
    short = tmp_path / "short.toml"
    short.write_text(text.replace("static_tension = 200.0", "length = 1.60"))
    _one_line_error(capsys, ["modal", str(short), "--out", str(tmp_path)], "too short")
