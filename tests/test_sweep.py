"""Batched parametric sweeps (beltjax.sweep): vmapped batches against case-by-case analyses,
tolerance statistics, failure reporting, Dask and sharded execution, sweep-file errors, the CLI.

The two-pulley bench with 4 elements per span keeps compilation short; every batch here runs
with the same options and chunk size, so they share one compiled function (see
``sweep.full_values``: the batch always carries every scalar parameter of the scene).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
import subprocess
import sys
import textwrap

import equinox as eqx
import numpy as np
import pytest

from beltjax import cli, drive, drive_modal, parameters, statics, sweep
from beltjax.scene import load_scene

REPO = pathlib.Path(__file__).resolve().parents[1]
T200 = REPO / "scenes" / "two_pulley_T200.toml"
OUTPUTS = ("statics", "modal")
MODES = 8
CHUNK = 8


def _small(scene, n=4):
    return eqx.tree_at(lambda s: s.model, scene, dataclasses.replace(scene.model, elements_per_span=n))


@pytest.fixture(scope="module")
def scene():
    """The thesis' two-pulley bench at T = 200 N, 4 elements per span."""
    return _small(load_scene(T200))


def _evaluate(scene, values, **kw):
    return sweep.evaluate(scene, values, OUTPUTS, MODES, chunk=CHUNK, **kw)


@pytest.fixture(scope="module")
def grid(scene):
    """Tension x EI grid (3 x 2 = 6 cases) and its batched result."""
    spec = sweep.parse_spec({"outputs": list(OUTPUTS), "modes": MODES, "grid": [
        {"parameter": "belt.static_tension", "values": [200, 350, 500]},
        {"parameter": "belt.EI", "start": 0.02, "stop": 0.05, "num": 2}]})
    values = sweep.cases(scene, spec)
    return values, _evaluate(scene, values)


def _tolerance_spec(rel):
    return sweep.parse_spec({"outputs": list(OUTPUTS), "modes": MODES, "samples": 48, "seed": 3, "random": [
        {"parameter": "pulley.alternator.center.x", "distribution": "normal", "nominal": True, "tolerance": 5e-4},
        {"parameter": "pulley.alternator.center.y", "distribution": "uniform", "nominal": True, "tolerance": 5e-4},
        {"parameter": "belt.length", "distribution": "normal", "nominal": True, "relative_tolerance": rel}]})


# --------------------------------------------------------------------------- batched = one by one


def test_grid_cases_are_full_factorial(grid):
    values, res = grid
    np.testing.assert_array_equal(values["belt.static_tension"], [200, 200, 350, 350, 500, 500])
    np.testing.assert_array_equal(values["belt.EI"], [0.02, 0.05] * 3)
    assert list(res["status"]) == ["ok"] * 6


def test_vmapped_batch_equals_cases_one_by_one(scene, grid):
    values, res = grid
    for i in range(6):
        sc = parameters.set_values(scene, {k: v[i] for k, v in values.items()})
        m = drive_modal.analyse_modes(sc)
        st = m.statics
        np.testing.assert_allclose(res["span_tensions_N"][i], st.span_tensions_N, rtol=1e-9)
        hubs = [np.hypot(*st.hub_forces_N[name]) for name in sc.route.order]
        np.testing.assert_allclose(res["hub_forces_N"][i], hubs, rtol=1e-9)
        assert res["belt_length_m"][i] == pytest.approx(st.belt_length_m, rel=1e-12)
        assert res["installation_tension_N"][i] == pytest.approx(values["belt.static_tension"][i], rel=1e-12)
        assert res["frequencies_hz"][i, 0] == 0.0  # the free drive's rigid-body mode
        # column k holds the nominal's k-th mode: the case's own mode of that kind and order (labelled
        # by its own modal analysis), whatever its rank in the case
        for k, lab in enumerate(res["mode_labels"][1:], start=1):
            same = [f for f, own in zip(m.frequencies_hz, m.labels) if own.split()[:2] == lab.split()[:2]]
            assert np.min(np.abs(np.asarray(same) - res["frequencies_hz"][i, k])) <= 1e-9 * same[0], (i, lab)
        np.testing.assert_allclose(np.sort(res["frequencies_hz"][i]), m.frequencies_hz[:MODES], rtol=1e-9)
        assert res["stable"][i] and res["converged"][i]


def test_frequency_columns_keep_their_mode_across_the_grid(grid):
    """The rotational mode (~96.5 Hz) stays in one column while the transverse modes rise through
    it with the tension (sorted, it moved from the 8th place at 200 N to the 6th at 350 N)."""
    _, res = grid
    F, labels = res["frequencies_hz"], res["mode_labels"]
    rot = [k for k, lab in enumerate(labels) if lab.startswith("1st rotational")]
    assert len(rot) == 1 and rot[0] == 7
    np.testing.assert_allclose(F[:, rot[0]], 96.5, rtol=0.005)
    rank = np.argsort(np.argsort(F, axis=1), axis=1)[:, rot[0]]
    assert rank[0] == 7 and rank[-1] < 7  # its rank changes across the cases, its column does not
    assert np.all(res["mode_mac"] > 0.99)
    trans = [k for k, lab in enumerate(labels) if lab.startswith("1st transverse")]
    assert len(trans) == 2
    np.testing.assert_allclose(F[:, trans[0]] / F[0, trans[0]], np.sqrt(res["installation_tension_N"] / 200), rtol=0.01)
    cols = sweep.columns(load_scene(T200), res)
    assert np.all(cols["mode_match"] > 0.99)


def test_frequencies_follow_the_tension(grid):
    _, res = grid
    f2 = res["frequencies_hz"][:, 1]  # 1st transverse: ~ sqrt(T)
    ratio = f2[4] / f2[0]
    assert ratio == pytest.approx(np.sqrt(500 / 200), rel=0.01)


# --------------------------------------------------------------------------- tolerance studies


@pytest.fixture(scope="module")
def tolerance(scene):
    out = {}
    for rel in (0.001, 0.003):
        spec = _tolerance_spec(rel)
        values = sweep.cases(scene, spec)
        out[rel] = (values, _evaluate(scene, values))
    return out


def test_tolerance_draws(scene, tolerance):
    L0 = float(statics.install(scene).belt_length)  # the nominal length of a tension-mode scene
    (v1, _), (v3, _) = tolerance[0.001], tolerance[0.003]
    # the same seed gives the same standard draws: the length deviations scale with the tolerance
    np.testing.assert_allclose(v3["belt.length"] - L0, 3 * (v1["belt.length"] - L0), rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(v1["pulley.alternator.center.x"], v3["pulley.alternator.center.x"])
    y = v1["pulley.alternator.center.y"] - 0.135  # uniform in +-0.5 mm
    assert np.all(np.abs(y) <= 5e-4) and np.ptp(y) > 5e-4
    assert np.std(v1["belt.length"] / L0 - 1) == pytest.approx(0.001 / 3, rel=0.35)


def test_tension_spread_grows_with_the_length_tolerance(tolerance):
    (_, r1), (_, r3) = tolerance[0.001], tolerance[0.003]
    t1 = r1["span_tensions_N"][:, 0]
    t3 = r3["span_tensions_N"][:, 0]
    assert list(r1["status"]).count("ok") == 48
    s1, s3 = np.std(t1), np.nanstd(t3)
    assert 20 < s1 < 80  # EA * 0.033 % (length) and the centre distance: about 40 N
    assert s3 > 2.0 * s1
    assert abs(np.mean(t1) - 200) < 4 * s1 / np.sqrt(48)  # unbiased about the nominal tension
    # belt frequencies spread with the tension; the rotational mode (~96 Hz) hardly moves
    f2 = r1["frequencies_hz"][:, 1]
    assert np.std(f2) / np.mean(f2) == pytest.approx(0.5 * s1 / np.mean(t1), rel=0.2)


def test_failed_cases_are_nan_with_a_status(scene, tolerance):
    values, res = tolerance[0.003]
    slack = res["status"] == "belt_slack"
    assert 0 < slack.sum() < 48  # a +0.3 % belt at T = 200 N (0.18 % stretch) hangs slack
    # independent check: those belts are longer than the belt path round the drawn layout
    for i in range(48):
        sc = parameters.set_values(scene, {k: v[i] for k, v in values.items()})
        path = float(sc.geometry().length)
        assert slack[i] == (values["belt.length"][i] >= path)
    assert np.all(np.isnan(res["span_tensions_N"][slack])) and np.all(np.isnan(res["frequencies_hz"][slack]))
    assert not res["converged"][slack].any()
    assert np.all(np.isfinite(res["span_tensions_N"][~slack]))
    f = sweep.failures(res)
    assert list(f) == ["belt_slack"] and f["belt_slack"]["count"] == slack.sum()
    assert f["belt_slack"]["cases"] == list(np.flatnonzero(slack)[:20])


def test_invalid_values_fail_alone(scene):
    values = {"belt.static_tension": np.array([300.0, 300.0, 300.0]), "belt.EA": np.array([111190.0, -5.0, np.nan])}
    res = _evaluate(scene, values)
    assert list(res["status"]) == ["ok", "invalid_value", "invalid_value"]
    assert np.isfinite(res["frequencies_hz"][0, 1:]).all() and np.isnan(res["frequencies_hz"][1:]).all()


def test_unconverged_cases_are_retried_with_speed_stepping(scene, monkeypatch):
    """As analyse_statics, a case whose Newton fails is run again with 8 speed steps (the
    retry's bookkeeping, with a stand-in for the compiled batch)."""
    not_converged = sweep.STATUS.index("not_converged")

    def fake_batch_fn(opts, devices, keys):
        def batch(scene, X, rpm, ref=None):
            EI = np.asarray(X)[:, keys.index("belt.EI")]
            assert EI.shape == (CHUNK,)  # always the padded chunk size: no recompilation
            fail = (opts.steps == 1) & (EI > 0.04)
            return {"code": np.where(fail, not_converged, 0),
                    "span_tensions_N": np.stack([EI, np.full(CHUNK, opts.steps)], axis=1),
                    "installation_tension_N": np.full(CHUNK, 200.0)}
        return batch

    monkeypatch.setattr(sweep.batch, "_batch_fn", fake_batch_fn)
    EI = np.array([0.02, 0.05, 0.03, 0.045, 0.01, 0.06, 0.02, 0.05, 0.05, 0.02])
    res = sweep.evaluate(scene, {"belt.EI": EI}, ("statics",), chunk=CHUNK)
    assert list(res["status"]) == ["ok"] * 10
    np.testing.assert_array_equal(res["span_tensions_N"][:, 0], EI)
    np.testing.assert_array_equal(res["span_tensions_N"][:, 1], np.where(EI > 0.04, 8, 1))


def test_grid_times_random_uses_common_draws(scene):
    spec = sweep.parse_spec({"samples": 3, "grid": [{"parameter": "belt.EA", "values": [1e5, 1.2e5]}],
                             "random": [{"parameter": "belt.EI", "distribution": "uniform", "low": 0.02,
                                         "high": 0.04, "seed": 7}]})
    v = sweep.cases(scene, spec)
    assert spec.n_cases == 6
    np.testing.assert_array_equal(v["belt.EA"], [1e5] * 3 + [1.2e5] * 3)
    np.testing.assert_array_equal(v["belt.EI"][:3], v["belt.EI"][3:])
    assert np.all((v["belt.EI"] >= 0.02) & (v["belt.EI"] <= 0.04))
    np.testing.assert_array_equal(sweep.cases(scene, spec)["belt.EI"], v["belt.EI"])  # seeded


# --------------------------------------------------------------------------- scale-out


def test_dask_local_cluster_equals_local(scene, tolerance):
    distributed = pytest.importorskip("dask.distributed")
    values, local = tolerance[0.003]  # 48 cases: 6 chunks, some of them with failed cases
    # worker threads in this process share the compiled batch; worker processes compile their own
    # (measured: 2 worker processes took 2.3 s to start and 12 s to compile, this sweep 0.1 s)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        seen = []
        res = sweep.evaluate(scene, values, OUTPUTS, MODES, chunk=CHUNK, backend="dask", dask=client,
                             progress=lambda done, total: seen.append(done))
    assert seen[-1] == 48 and len(seen) == 6
    assert list(res["status"]) == list(local["status"])
    for k in ("span_tensions_N", "hub_forces_N", "frequencies_hz", "belt_length_m"):
        np.testing.assert_array_equal(np.isnan(res[k]), np.isnan(local[k]))
        np.testing.assert_allclose(res[k], local[k], rtol=1e-12, atol=1e-9)


def test_dask_missing_is_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    with pytest.raises(sweep.SweepError, match=r"beltjax\[dask\]"):
        sweep._dask_client_check()


# the grid fixture's cases, sharded over two host devices (statics only: with the eigen-solves
# XLA's CPU runtime wedged on two host devices, see sweep._devices), in a subprocess started
# early so that its compilation overlaps the tests before it
_SHARDED = textwrap.dedent("""
    import dataclasses, json, sys
    import equinox as eqx, jax, numpy as np
    from beltjax import sweep
    from beltjax.scene import load_scene
    sc = load_scene(sys.argv[1])
    sc = eqx.tree_at(lambda s: s.model, sc, dataclasses.replace(sc.model, elements_per_span=4))
    values = {"belt.static_tension": np.repeat([200.0, 350.0, 500.0], 2), "belt.EI": np.tile([0.02, 0.05], 3)}
    a = sweep.evaluate(sc, values, ("statics",), chunk=4, devices=jax.devices())
    print(json.dumps(dict(devices=len(jax.devices()), status=list(a["status"]),
                          tensions=a["span_tensions_N"].tolist(), hubs=a["hub_forces_N"].tolist())))
""")


@pytest.fixture(scope="module", autouse=True)
def sharded_run():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", OPENBLAS_NUM_THREADS="1")
    p = subprocess.Popen([sys.executable, "-c", _SHARDED, str(T200)], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    yield p
    if p.poll() is None:
        p.kill()
        p.communicate()


def test_sharded_batch_over_two_host_devices_equals_unsharded(sharded_run, grid):
    _, local = grid
    stdout, stderr = sharded_run.communicate(timeout=300)
    assert sharded_run.returncode == 0, stderr[-2000:]
    out = json.loads(stdout.strip().splitlines()[-1])
    assert out["devices"] == 2 and out["status"] == ["ok"] * 6
    np.testing.assert_allclose(out["tensions"], local["span_tensions_N"], rtol=1e-12)
    np.testing.assert_allclose(out["hubs"], local["hub_forces_N"], rtol=1e-12)


# --------------------------------------------------------------------------- sweep files


BAD = [
    ({"grid": [{"parameter": "belt.EI", "values": [0.02]}], "foo": 1}, "foo"),
    ({}, "grid"),
    ({"grid": [{"parameter": "belt.Ei", "values": [0.02]}]}, "grid[0].parameter"),
    ({"grid": [{"parameter": "pulley.idler.radius", "values": [0.02]}]}, "grid[0].parameter"),
    ({"grid": [{"parameter": "belt.EI", "values": [0.02, "x"]}]}, "grid[0].values[1]"),
    ({"grid": [{"parameter": "belt.EI", "values": []}]}, "grid[0].values"),
    ({"grid": [{"parameter": "belt.EI", "start": 0.01, "stop": 0.02, "num": 0}]}, "grid[0].num"),
    ({"grid": [{"parameter": "belt.EI", "start": 0.01, "stop": 0.02}]}, "grid[0].num"),
    ({"grid": [{"parameter": "belt.EI", "values": [0.02], "colour": 1}]}, "grid[0].colour"),
    ({"grid": [{"parameter": "belt.EI", "values": [-0.02, 0.02]}]}, "grid[0].values"),
    ({"grid": [{"parameter": "belt.EI", "start": 1e-3, "stop": 1e-2, "num": 400},
               {"parameter": "belt.EA", "start": 1e5, "stop": 2e5, "num": 400}]}, "grid[1]"),
    ({"random": [{"parameter": "belt.EI", "distribution": "normal", "mean": 0.03, "std": -1.0}], "samples": 5},
     "random[0].std"),
    ({"random": [{"parameter": "belt.EI", "distribution": "normal", "mean": 0.03, "std": 0.01}]}, "samples"),
    ({"random": [{"parameter": "belt.EI", "distribution": "gamma", "mean": 0.03, "std": 0.01}], "samples": 5},
     "random[0].distribution"),
    ({"random": [{"parameter": "belt.EI", "distribution": "normal", "std": 0.01}], "samples": 5}, "random[0].mean"),
    ({"random": [{"parameter": "belt.EI", "distribution": "uniform", "low": 0.03, "high": 0.01}], "samples": 5},
     "random[0].high"),
    ({"random": [{"parameter": "belt.EI", "distribution": "normal", "nominal": True, "std": 0.01, "samples": 4},
                 {"parameter": "belt.EA", "distribution": "normal", "nominal": True, "std": 10, "samples": 5}]},
     "random[1].samples"),
    ({"random": [{"parameter": "belt.EI", "distribution": "normal", "nominal": True, "relative_tolerance": 1.5}],
      "samples": 5}, "random[0].relative_tolerance"),
    ({"grid": [{"parameter": "belt.static_tension", "values": [200]}, {"parameter": "belt.length", "values": [1.79]}]},
     "grid[1].parameter"),
    ({"grid": [{"parameter": "belt.EI", "values": [0.02]}, {"parameter": "belt.EI", "values": [0.03]}]},
     "grid[1].parameter"),
    ({"outputs": ["statics", "modes"], "grid": [{"parameter": "belt.EI", "values": [0.02]}]}, "outputs[1]"),
    ({"outputs": ["campbell"], "grid": [{"parameter": "belt.EI", "values": [0.02]}]}, "rpm"),
    ({"outputs": ["campbell"], "rpm": [0, 100, 0], "grid": [{"parameter": "belt.EI", "values": [0.02]}]}, "rpm[2]"),
    ({"modes": 0, "grid": [{"parameter": "belt.EI", "values": [0.02]}]}, "modes"),
]


@pytest.mark.parametrize("data,key", BAD, ids=[k for _, k in BAD])
def test_bad_sweep_files_name_the_key(scene, data, key):
    with pytest.raises(sweep.SweepError) as exc:
        spec = sweep.parse_spec(data)
        sweep.check_spec(scene, spec)
    msg = str(exc.value)
    assert msg.startswith(key) and "\n" not in msg, msg


def test_example_sweep_files_parse(scene):
    for name, n in (("two_pulley_tension_EI", 20), ("two_pulley_tolerance", 200)):
        spec = sweep.load_spec(REPO / "scenes" / "sweeps" / f"{name}.toml")
        assert spec.n_cases == n
        sweep.check_spec(scene, spec)


# --------------------------------------------------------------------------- command line


@pytest.fixture(scope="module")
def small_scene_file(tmp_path_factory):
    text = T200.read_text().replace("elements_per_span = 16", "elements_per_span = 4")
    assert "elements_per_span = 4" in text
    path = tmp_path_factory.mktemp("scene") / "two_pulley_small.toml"
    path.write_text(text)
    return path


def test_cli_sweep_end_to_end(small_scene_file, tmp_path, capsys):
    spec = tmp_path / "tiny.toml"
    spec.write_text(textwrap.dedent(f"""
        description = "tiny sweep"
        outputs = ["statics", "modal"]
        modes = {MODES}
        chunk = {CHUNK}
        samples = 4
        [[grid]]
        parameter = "belt.static_tension"
        values = [200, 400]
        [[random]]
        parameter = "pulley.alternator.center.x"
        distribution = "uniform"
        nominal = true
        tolerance = 0.0005
    """))
    out = tmp_path / "out"
    assert cli.main(["sweep", str(small_scene_file), str(spec), "--out", str(out)]) == 0
    printed = capsys.readouterr()
    assert "8 ok, 0 failed, 0 unstable" in printed.out and "1st transverse" in printed.out
    assert "8/8 cases" in printed.err  # the progress bar
    rows = (out / "sweep.csv").read_text().splitlines()
    head = rows[0].split(",")
    assert head[:3] == ["case", "belt.static_tension", "pulley.alternator.center.x"]
    assert head[-1] == "status" and "tension_crank-alternator_N" in head and "f2_hz" in head
    assert len(rows) == 9 and all(r.endswith(",ok") for r in rows[1:])
    data = json.loads((out / "sweep.json").read_text())
    assert data["n_cases"] == 8 and data["ok"] == 8 and data["failed"] == 0
    s = data["summary"]["tension_crank-alternator_N"]
    assert s["min"] == pytest.approx(200, rel=1e-9) and s["max"] == pytest.approx(400, rel=1e-9)
    assert data["nominal_modes"]["labels"][0] == "rigid body"
    assert data["cases_per_s"] > 0 and data["spec"]["samples"] == 4
    for png in ("sweep_frequencies.png", "sweep_statics.png", "sweep_histograms.png"):
        assert (out / png).stat().st_size > 1000


def test_cli_sweep_bad_file_is_one_line(small_scene_file, tmp_path, capsys):
    spec = tmp_path / "bad.toml"
    spec.write_text('[[grid]]\nparameter = "pulley.alternator.centre.x"\nvalues = [0.22]\n')
    assert cli.main(["sweep", str(small_scene_file), str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("beltjax: error: grid[0].parameter: pulley.alternator.centre.x") and "\n" not in err


def test_campbell_output(scene, grid, tmp_path, capsys):
    """Frequencies against the drive pulley's speed per case (beltjax.sweep ran the same cases as
    campbell.campbell_frequencies to 1e-12 when written; that comparison costs a second compilation)."""
    spec = tmp_path / "campbell.toml"
    spec.write_text('outputs = ["campbell"]\nmodes = 8\nrpm = [0, 2000, 2000]\n'
                    '[[grid]]\nparameter = "belt.static_tension"\nvalues = [200, 500]\n'
                    '[[grid]]\nparameter = "belt.EI"\nvalues = [0.02]\n')
    assert sweep.run(scene, spec, tmp_path, backend="local") == 0
    capsys.readouterr()
    rows = np.genfromtxt(tmp_path / "sweep_campbell.csv", delimiter=",", names=True)
    assert len(rows) == 4 and (tmp_path / "sweep_campbell.png").exists()
    F = np.stack([rows[f"f{m + 1}_hz"] for m in range(MODES)], axis=1).reshape(2, 2, MODES)  # case, rpm, mode
    assert np.all(rows["stable"] == 1)
    # at rest the gyroscopic route gives the modal frequencies (grid cases 0 and 4: T = 200, 500 N, EI = 0.02)
    _, modal = grid
    np.testing.assert_allclose(F[:, 0, 1:], modal["frequencies_hz"][[0, 4], 1:], rtol=1e-8)
    # a moving string's frequencies fall as 1 - rhoA v^2 / T (the bench's spans within 1 %)
    v = float(drive.belt_speed(scene, 2000.0))
    for i, T in enumerate((200.0, 500.0)):
        expected = 1 - float(scene.belt.rhoA) * v**2 / T
        assert F[i, 1, 1] / F[i, 0, 1] == pytest.approx(expected, rel=0.01)
    data = json.loads((tmp_path / "sweep.json").read_text())
    assert data["summary"]["campbell_unstable_from_rpm"]["count"] == 0  # stable up to 2000 rpm


def test_summary_table_never_cuts_a_name():
    """Output names as long as a long pulley name makes them are printed whole."""
    name = "hub_" + "power_steering_pump_with_a_very_long_name_" * 2 + "N"
    stats = {name: sweep.statistics(np.array([1.0, 2.0])), "tension_a-b_N": sweep.statistics(np.array([3.0]))}
    text = sweep.summary_table({name: None, "tension_a-b_N": None}, stats)
    assert name in text and "tension_a-b_N" in text
    assert len(text.splitlines()) == 3


def test_flags_on_a_computed_cycle_keep_their_numbers():
    """The one policy of sweeps and responses over speed (beltjax.orders.FLAGS_KEEPING_NUMBERS): a
    span slack in the steady cycle, or a cycle not settled, keeps the case's numbers beside its
    status (flagged) and out of the pooled statistics; the same status from the statics (a slack
    span at the operating point) or a failed transient leaves NaN."""
    from beltjax import orders
    from beltjax.sweep import batch, tables

    code = np.array([sweep.STATUS.index(s) for s in ("ok", "span_slack", "span_slack", "not_settled",
                                                     "transient_failed")])
    out = {"code": code, "flag_keeps": np.array([False, True, False, True, False]),
           "response_arm_p2p_deg": np.array([1.0, 2.0, 3.0, 4.0, 5.0])}
    res = batch._finish(out, np.zeros(5, int), np.array([]))
    assert set(orders.FLAGS_KEEPING_NUMBERS) == {"span_slack", "not_settled"}
    np.testing.assert_array_equal(res["response_arm_p2p_deg"], [1.0, 2.0, np.nan, 4.0, np.nan])
    np.testing.assert_array_equal(res["flagged"], [False, True, False, True, False])
    pooled = tables.pooled({"arm_p2p_deg": res["response_arm_p2p_deg"]}, res)["arm_p2p_deg"]
    assert tables.statistics(pooled)["count"] == 1 and tables.statistics(pooled)["max"] == 1.0



# --------------------------------------------------------------------------- absurd spreads

_EA = {"parameter": "belt.EA", "distribution": "normal", "nominal": True}
_SPREADS = [
    (dict(_EA, std=1e300), "random[0].std", "the band 111190 +- 3 std = [-3e+300, 3e+300] leaves the accepted "
                                            "range of belt.EA, [1, 1e+10] N"),
    (dict(_EA, std=4e4), "random[0].std", "= [-8810, 231190] leaves the accepted range of belt.EA"),
    (dict(_EA, std=1.5e308), "random[0].std", "is not finite"),
    (dict(_EA, std=0.0), "random[0].std", "must be > 0, got 0.0"),
    (dict(_EA, distribution="uniform", nominal=False, mean=5e9, tolerance=6e9), "random[0].tolerance",
     "the band 5e+09 +- tolerance = [-1e+09, 1.1e+10] leaves"),
    (dict(_EA, nominal=False, mean=9e9, relative_tolerance=0.5), "random[0].relative_tolerance",
     "+- relative_tolerance x |centre| = [4.5e+09, 1.35e+10] leaves"),
    (dict(_EA, tolerance=0), "random[0].tolerance", "must be > 0"),
]


@pytest.mark.parametrize("axis, key, phrase", _SPREADS, ids=[f"{k}-{i}" for i, (_, k, _) in enumerate(_SPREADS)])
def test_a_spread_beyond_the_parameters_range_is_refused(scene, axis, key, phrase):
    """A band centre +- spread (3 std for std) must lie in the parameter's accepted range, as low
    and high must (std = 1e300 exited 1 with a numpy overflow warning, every case invalid_value)."""
    with pytest.raises(sweep.SweepError) as exc:
        sweep.check_spec(scene, sweep.parse_spec({"samples": 2, "random": [axis]}))
    msg = str(exc.value)
    assert exc.value.key == key and msg.startswith(key + ": ") and phrase in msg and "\n" not in msg, msg


def test_a_spread_inside_the_range_is_drawn(scene):
    values = sweep.cases(scene, sweep.parse_spec({"samples": 200, "random": [dict(_EA, std=3e4)]}))["belt.EA"]
    assert np.all(np.isfinite(values)) and abs(np.std(values) / 3e4 - 1) < 0.2


def test_cli_huge_std_is_one_line_without_a_warning(small_scene_file, tmp_path, capfd):
    """The fuzzer's case 13, run as a user runs it (a child process: every warning reaches stderr)."""
    spec = tmp_path / "huge_std.toml"
    spec.write_text('outputs = ["statics"]\n[[random]]\nparameter = "belt.EA"\ndistribution = "normal"\n'
                    'nominal = true\nstd = 1e300\nsamples = 2\n')
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "beltjax", "sweep", str(small_scene_file), str(spec), "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().splitlines() == [r.stderr.strip()] and "RuntimeWarning" not in r.stderr, r.stderr
    assert r.stderr.startswith("beltjax: error: random[0].std: the band") and not out.exists()


def test_draws_and_statistics_never_warn():
    """Past the checks (an API caller's axis), a draw that overflows is a non-finite value (its case
    invalid_value), and the statistics of huge values are computed without overflow."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        axis = sweep.RandomAxis("belt.EA", "normal", 1.0, std=1e308)
        assert not np.all(np.isfinite(sweep._draw(axis, 1.0, 8, 0)))
        s = sweep.statistics(np.array([1e308, -1e308, 1.7e308]))
    assert s["mean"] == pytest.approx(1.7e308 / 3) and math.isfinite(s["std"]) and s["p50"] == 1e308


def test_a_parameter_path_with_white_space_is_quoted(scene):
    """" belt.EA" was named belt.EA, which looks valid."""
    with pytest.raises(sweep.SweepError) as exc:
        sweep.check_spec(scene, sweep.parse_spec({"grid": [{"parameter": " belt.EA", "values": [1e5]}]}))
    assert str(exc.value).startswith("grid[0].parameter: ' belt.EA': "), str(exc.value)
