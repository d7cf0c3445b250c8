"""The `beltjax span` command: outputs, and one-line errors for bad input."""

import json
import math
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

from beltjax.cli import main

GOOD = ["span", "--length", "0.67143", "--tension", "100.5", "--EA", "111190", "--EI", "0.034",
        "--rhoA", "0.12166", "--elements", "8"]


def _with(flag, value):
    args = list(GOOD)
    i = args.index(flag)
    args[i + 1] = value
    return args


def _without(flag):
    args = list(GOOD)
    i = args.index(flag)
    del args[i:i + 2]
    return args


BAD = [
    (_with("--EA", "-1"), "--EA"), (_with("--EA", "0"), "--EA"),
    (_with("--EI", "-0.03"), "--EI"), (_with("--EI", "0"), "--EI"),
    (_with("--rhoA", "0"), "--rhoA"), (_with("--rhoA", "-2"), "--rhoA"),
    (_with("--length", "0"), "--length"), (_with("--length", "-0.5"), "--length"),
    (_with("--tension", "0"), "--tension"), (_with("--tension", "-100"), "--tension"),
    (_with("--tension", "abc"), "--tension"), (_with("--EA", "1e5N"), "--EA"),
    (_with("--tension", "nan"), "--tension"), (_with("--EI", "inf"), "--EI"),
    (_with("--elements", "1"), "--elements"), (_with("--elements", "0"), "--elements"),
    (_with("--elements", "2.5"), "--elements"), (_without("--EA"), "--EA"),
    (_without("--length"), "--length"), (GOOD + ["--bc", "welded"], "--bc"),
    (GOOD + ["--speed", "fast"], "--speed"), ([], "command"),
]


@pytest.mark.parametrize("argv,name", BAD, ids=[" ".join(a[-2:]) if a else "empty" for a, _ in BAD])
def test_bad_input_gives_one_line_naming_the_argument(argv, name, capsys, tmp_path):
    code = main(argv + ["--out", str(tmp_path)] if argv else argv)
    err = capsys.readouterr().err.strip()
    assert code != 0
    assert len(err.splitlines()) == 1, err
    assert name in err and err.startswith("beltjax: error:"), err
    assert "Traceback" not in err
    assert not (tmp_path / "span.json").exists()


def test_span_command_writes_json_plot_and_table(tmp_path, capsys):
    code = main(GOOD + ["--speed", "10", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    data = json.loads((tmp_path / "span.json").read_text())
    f = data["frequencies_hz"]
    assert data["stable"] is True and len(f) == len(data["labels"]) > 10
    assert f == sorted(f) and all(math.isfinite(x) for x in f)
    assert all(("transverse" in lab or "longitudinal" in lab) and lab[0].isdigit() for lab in data["labels"])
    assert data["labels"][0] == "1st transverse"
    assert (tmp_path / "span_modes.png").stat().st_size > 10_000
    assert "1st transverse" in out and "critical speed" in out


def test_span_command_reports_supercritical_speed(tmp_path, capsys):
    code = main(GOOD + ["--speed", "40", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    data = json.loads((tmp_path / "span.json").read_text())
    assert code == 0  # a valid question with an honest answer: the span is unstable
    assert data["stable"] is False and data["frequencies_hz"] == [] and data["unstable_eigenvalues"]
    assert "UNSTABLE" in out


def test_installed_entry_point_runs(tmp_path):
    exe = shutil.which("beltjax") or str(pathlib.Path(sys.executable).parent / "beltjax")
    proc = subprocess.run([exe, *GOOD, "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "1st transverse" in proc.stdout
    bad = subprocess.run([exe, *_with("--EA", "-5"), "--out", str(tmp_path)], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode != 0 and len(bad.stderr.strip().splitlines()) == 1 and "--EA" in bad.stderr


def test_campbell_orders_beyond_the_schema_are_one_line(tmp_path):
    """`campbell --orders 1e300` exited 0 with overflow warnings and crossings "order 1e+300x"."""
    scene = pathlib.Path(__file__).resolve().parents[1] / "scenes" / "two_pulley_T200.toml"
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "beltjax", "campbell", str(scene), "--rpm", "0:100:50", "--orders",
                        "2,1e300", "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip() == ("beltjax: error: orders[1]: must lie in [0, 1000] - (cycles per revolution: engines "
                                "excite orders up to about 20), got 1e+300"), r.stderr
    assert not out.exists()


@pytest.mark.parametrize("text,speeds", [
    ("800:1000:300", [800.0, 1000.0]),  # B is not on the grid: it ends the range, nothing beyond it
    ("800:1100:300", [800.0, 1100.0]),
    ("0:1:0.1", [0.1 * i for i in range(10)] + [1.0]),  # round-off neither adds a speed past B nor drops B
    ("0:0.3:0.1", [0.0, 0.1, 0.2, 0.3]),
    ("600:6000:100", [600.0 + 100 * i for i in range(55)]),
    ("5:5:1", [5.0]),
    ("0:10:4", [0.0, 4.0, 8.0, 10.0]),
])
def test_a_speed_range_runs_from_a_by_step_and_ends_at_b(text, speeds):
    """--rpm A:B:STEP and a sweep's rpm = [A, B, STEP] read alike (validate.rpm_range): every
    speed in [A, B], B itself the last."""
    from beltjax import cli, sweep

    got = cli._rpm_range(text)
    np.testing.assert_allclose(got, speeds, rtol=1e-12, atol=0)
    assert got[-1] == float(text.split(":")[1]) and got[0] == float(text.split(":")[0])
    assert np.all(np.diff(got) > 0)
    np.testing.assert_array_equal(sweep._rpm_range("rpm", [float(x) for x in text.split(":")]), got)


def test_a_speed_range_with_too_many_speeds_is_one_line(capsys, tmp_path):
    from beltjax.sweep import SweepError, _rpm_range

    assert main(["campbell", "x.toml", "--rpm", "0:1e6:0.01", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "argument --rpm: --rpm gives 100000001 speeds, at most" in err, err
    with pytest.raises(SweepError, match=r"^rpm: gives 100000001 speeds, at most"):
        _rpm_range("rpm", [0.0, 1e6, 0.01])
