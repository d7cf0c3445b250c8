"""The drive commands `beltjax statics`, `modal`, `campbell` and `simulate`: outputs, and one-line errors.

The full runs call the command's entry function in this process (they share its compiled
statics; each writes its persistent compile cache under BELTJAX_CACHE, a temporary folder);
the bad-input cases stop before any compilation.  tests/test_cli.py runs the installed
``beltjax`` program.
"""

import json
import math
import pathlib
import tomllib

import numpy as np
import pytest

from beltjax.cli import main

REPO = pathlib.Path(__file__).resolve().parents[1]
T200 = REPO / "scenes" / "two_pulley_T200.toml"


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One persistent JAX compile cache for the whole module."""
    return tmp_path_factory.mktemp("jax_cache")


@pytest.fixture(autouse=True)
def _use_cache(cache, monkeypatch):
    monkeypatch.setenv("BELTJAX_CACHE", str(cache))


def run_cli(*args, cache, capsys):
    """The command run in this process (``beltjax.cli.main``, as the entry point calls it): its
    exit status 0, and what it printed (``.stdout``, ``.stderr``).  In-process, the four commands
    share their compiled statics; tests/test_cli.py runs the installed entry point itself."""
    capsys.readouterr()
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    assert code == 0, out.err
    return out


# --------------------------------------------------------------------------- full runs


def test_statics_command(tmp_path, cache, capsys):
    out = tmp_path / "st"
    proc = run_cli("statics", T200, "--out", out, cache=cache, capsys=capsys)
    data = json.loads((out / "statics.json").read_text())
    for key in ("span_names", "span_tensions_N", "span_lengths_m", "belt_length_m", "installation_tension_N",
                "stretch", "hub_forces_N", "hub_force_magnitudes_N", "wrap_angles_deg", "speed_m_s"):
        assert key in data, key
    assert data["span_names"] == ["crank-alternator", "alternator-crank"]
    assert len(data["span_tensions_N"]) == 2
    assert all(abs(T - 200.0) < 2.0 for T in data["span_tensions_N"]), data["span_tensions_N"]
    assert 1.7 < data["belt_length_m"] < 1.9 and data["stretch"] > 1.0
    F = {k: np.array(v) for k, v in data["hub_forces_N"].items()}
    assert set(F) == {"crank", "alternator"}
    np.testing.assert_allclose(F["crank"], -F["alternator"], atol=1e-6)  # the belt is in equilibrium
    assert 0.95 * 400 < np.hypot(*F["crank"]) <= 400.0  # nearly parallel spans: about 2 T
    assert F["crank"][0] < 0  # the belt pulls the crank towards the alternator (smaller x)
    assert "tensioner_angle_deg" not in data
    assert (out / "layout.png").stat().st_size > 10_000
    assert "crank-alternator" in proc.out and "200.00" in proc.out and "statics.json" in proc.out


def test_modal_command(tmp_path, cache, capsys):
    out = tmp_path / "mo"
    proc = run_cli("modal", T200, "--modes", "10", "--out", out, cache=cache, capsys=capsys)
    data = json.loads((out / "modal.json").read_text())
    f, labels = data["frequencies_hz"], data["labels"]
    assert data["stable"] is True and len(f) == len(labels) == 10
    assert all(math.isfinite(x) for x in f) and f == sorted(f)
    assert labels[0] == "rigid body" and f[0] == 0.0  # both pulleys free: the belt turns as a whole
    # first transverse modes of the two equal spans: tensioned string n/(2L) sqrt(T/rhoA), within 2 %
    L = 0.6742
    f1 = 1 / (2 * L) * math.sqrt(200.0 / 0.12101)
    assert abs(f[1] - f1) < 0.02 * f1 and abs(f[2] - f[1]) < 1e-3 * f[1]
    assert all("transverse" in lab for lab in labels[1:3])
    assert (out / "modes.png").stat().st_size > 10_000
    assert "1st transverse" in proc.out and "modal.json" in proc.out


def test_campbell_command(tmp_path, cache, capsys):
    out = tmp_path / "ca"
    proc = run_cli("campbell", T200, "--rpm", "0:2000:500", "--modes", "6", "--out", out, cache=cache, capsys=capsys)
    data = json.loads((out / "campbell.json").read_text())
    assert data["rpm"] == [0.0, 500.0, 1000.0, 1500.0, 2000.0]
    F = np.array(data["frequencies_hz"], dtype=float)
    # one column per tracked mode: every mode among the 6 lowest at some speed (a repeated pair whole)
    assert F.shape[0] == 5 and F.shape[1] >= 6 and len(data["labels"]) == F.shape[1] and len(data["stable"]) == 5
    assert "tracked mode" in data["frequencies_meaning"]
    assert all(data["stable"]) and np.all(np.isfinite(F))
    assert np.all(np.diff(F[0]) >= -1e-9)  # columns ascending at the lowest speed
    transport = "transport" in tomllib.loads(T200.read_text())["model"].get("effects", [])
    assert data["orders"] == [1.0, 2.0, 3.0] and data["transport_effect"] is transport
    if transport:  # the moving belt softens the transverse modes: frequencies fall with speed
        assert F[-1, 1] < 0.99 * F[0, 1] and np.all(F[-1, 1:] > 0.5 * F[0, 1:])
    else:
        np.testing.assert_allclose(F, F[:1].repeat(5, axis=0), rtol=1e-8)  # independent of speed
        assert "transport" in proc.out  # the note saying so
    assert data["crossings"], "the first transverse modes (~30 Hz) cross 2x and 3x below 2000 rpm"
    for c in data["crossings"]:
        assert 0 <= c["rpm"] <= 2000 and c["order"] in (1.0, 2.0, 3.0)
        assert abs(c["frequency_hz"] - c["order"] * c["rpm"] / 60) < 1e-6
        assert c["curve_label"] == data["labels"][c["mode"] - 1] and "transverse" in c["label"]
    assert (out / "campbell.png").stat().st_size > 10_000
    assert "crossings" in proc.out and "campbell.json" in proc.out
    assert "followed across speeds by its shape" in proc.out and "sorted" not in proc.out
    assert "campbell: 5/5 speeds" in proc.err  # progress goes to stderr


def test_simulate_command(tmp_path, cache, capsys):
    """Rotational model of the T = 200 N bench, alternator released from a 2 deg rotation."""
    text = T200.read_text().replace('fidelity = "ancf"', 'fidelity = "rotational"')
    scene = tmp_path / "release.toml"
    scene.write_text(text + "\n[initial]\nrotation_deg = { alternator = 2.0 }\n")
    out = tmp_path / "si"
    proc = run_cli("simulate", scene, "--t-end", "0.25", "--dt", "2e-4", "--out", out, cache=cache, capsys=capsys)
    data = json.loads((out / "simulation.json").read_text())
    # no [simulation] solver: the rotational default, adaptive Dopri8 (--dt is its first step)
    assert data["meta"]["solver"] == "dopri8" and data["meta"]["fidelity"] == "rotational"
    assert data["meta"]["steps"] >= 25 and data["units"]["span_tensions_N"] == "N"  # >= 1 step per 97 Hz period
    T = data["channels"]["span_tensions_N"]
    assert set(T) == {"crank-alternator", "alternator-crank"}
    for st in T.values():  # oscillates about the installation tension at the torsional mode
        assert abs(st["mean"] - 200.0) < 5.0 and st["peak_to_peak"] > 100.0
        assert 80.0 < st["dominant_hz"][0] < 110.0
    npz = np.load(out / "simulation.npz")
    assert npz["t_s"][0] == 0.0 and abs(npz["t_s"][-1] - 0.25) < 1e-9
    assert npz["span_tensions_N"].shape == (len(npz["t_s"]), 2)
    assert list(npz["hub_forces_N__columns"]) == ["crank", "alternator"]
    assert np.all(np.isfinite(npz["hub_forces_N"]))
    for png in ("simulation.png", "spectra.png"):
        assert (out / png).stat().st_size > 10_000
    assert "dominant" in proc.out and "simulation.npz" in proc.out
    assert "simulate [" in proc.err  # the progress bar goes to stderr


# --------------------------------------------------------------------------- bad input (no compilation)


def _scene_variant(tmp_path, old, new, name="variant.toml"):
    text = T200.read_text()
    assert old in text
    p = tmp_path / name
    p.write_text(text.replace(old, new))
    return p


BAD = [
    (["campbell", str(T200), "--rpm", "0:2000"], "--rpm"),
    (["campbell", str(T200), "--rpm", "a:b:c"], "--rpm"),
    (["campbell", str(T200), "--rpm", "0:2000:0"], "--rpm"),
    (["campbell", str(T200), "--rpm", "0:2000:-50"], "--rpm"),
    (["campbell", str(T200), "--rpm", "2000:0:50"], "--rpm"),
    (["campbell", str(T200), "--rpm=-100:2000:50"], "--rpm"),
    (["campbell", str(T200), "--rpm", "-100:2000:50"], "--rpm"),
    (["campbell", str(T200), "--rpm", "0:100000:1"], "--rpm"),
    (["campbell", str(T200), "--rpm", "0:nan:5"], "--rpm"),
    (["campbell", str(T200)], "--rpm"),
    (["campbell", str(T200), "--rpm", "0:2000:500", "--orders=-1,2"], "--orders"),
    (["campbell", str(T200), "--rpm", "0:2000:500", "--orders", "1,x"], "--orders"),
    (["campbell", str(T200), "--rpm", "0:2000:500", "--orders", "0"], "--orders"),
    (["campbell", str(T200), "--rpm", "0:2000:500", "--modes", "0"], "--modes"),
    (["modal", str(T200), "--modes", "0"], "--modes"),
    (["modal", str(T200), "--modes", "2.5"], "--modes"),
    (["modal", str(T200), "--rpm=-5"], "--rpm"),
    (["modal", str(T200), "--rpm", "fast"], "--rpm"),
    (["statics"], "scene"),
    (["statics", str(T200), "--speed", "3"], "--speed"),
    (["simulate", str(T200)], "--t-end"),
    (["simulate", str(T200), "--t-end", "0"], "--t-end"),
    (["simulate", str(T200), "--t-end", "inf"], "--t-end"),
    (["simulate", str(T200), "--t-end", "1", "--dt", "-1e-4"], "--dt"),
    (["simulate", str(T200), "--t-end", "1", "--output-dt", "fast"], "--output-dt"),
    (["simulate", str(T200), "--t-end", "1", "--settle", "1.5"], "--settle"),
]


@pytest.mark.parametrize("argv,name", BAD, ids=[" ".join(a[2:]) or " ".join(a) for a, _ in BAD])
def test_bad_arguments_give_one_line_naming_the_argument(argv, name, capsys, tmp_path):
    out = tmp_path / "out"
    code = main(argv + ["--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert name in err and err.startswith("beltjax: error:"), err
    assert "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("command", ["statics", "modal", "campbell", "simulate"])
def test_missing_scene_file(command, capsys, tmp_path):
    missing = tmp_path / "no_such_scene.toml"
    extra = {"campbell": ["--rpm", "0:1000:500"], "simulate": ["--t-end", "1"]}.get(command, [])
    code = main([command, str(missing), *extra, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert str(missing) in err and "not found" in err
    assert not (tmp_path / "out").exists()


def test_scene_with_unknown_key(capsys, tmp_path):
    p = _scene_variant(tmp_path, "rhoA = 0.12101", "rhoA = 0.12101\nstiffnes = 3.0")
    code = main(["modal", str(p), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "belt.stiffnes" in err and "unknown key" in err and str(p) in err


def test_belt_too_short(capsys, tmp_path):
    p = _scene_variant(tmp_path, "static_tension = 200.0", "length = 1.60")
    code = main(["statics", str(p), "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "too short" in err and "belt.length" in err, err
    assert not (tmp_path / "out" / "statics.json").exists()
