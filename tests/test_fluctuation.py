"""The drive pulley's angle fluctuation as a list of orders, fixed frequencies or a measured speed
trace ([[fluctuation]], beltjax.scene.fluctuations), through the kinematic map into transients."""

from __future__ import annotations

import math
import pathlib
import re

import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import drive, excitation, transient
from beltjax.errors import BeltjaxError
from beltjax.scene import loads_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]
# the eight-pulley drive without its [[fluctuation]] tables (each test gives its own)
FEAD = re.sub(r"\[\[fluctuation\]\].*(?:\n(?!\[).*)*\n?", "", (ROOT / "scenes" / "fead_8pulley.toml").read_text())
W = 800 * 2 * math.pi / 60  # the drive's idle speed, rad/s


def _scene(tables: str, extra_crank: str = "") -> str:
    text = FEAD
    if extra_crank:
        text = text.replace('name = "crank"', 'name = "crank"\n' + extra_crank, 1)
    return text + "\n" + tables


def _order(n, amp, phase=0.0, pulley="crank"):
    return f'[[fluctuation]]\npulley = "{pulley}"\norder = {n}\namplitude_deg = {amp}\nphase_deg = {phase}\n'


def _fluct(scene, t):
    """The drive pulley's angle less its mean rotation (rad) at times t."""
    R = float(scene.pulley("crank").radius)
    return np.array([float(drive.belt_travel(scene, jnp.float64(x))) / R - W * x for x in t])


def test_second_order_is_the_pulley_harmonic():
    """Order 2 at 800 rpm is the pulley's own 26.667 Hz harmonic: the same kinematic map."""
    ts = np.linspace(0.0, 0.2, 37)
    a = loads_scene(_scene("", extra_crank=f"fluctuation_amplitude_deg = 0.5\nfluctuation_frequency_hz = {2 * 800 / 60!r}"))
    b = loads_scene(_scene(_order(2.0, 0.5)))
    assert np.allclose(_fluct(a, ts), _fluct(b, ts), rtol=0, atol=1e-12)


def test_orders_sum_and_follow_the_speed_in_a_run_up():
    """Several orders add; in a run-up each follows the mean rotation (not a fixed frequency)."""
    run_up = "acceleration_rpm_per_s = 3000.0\ntarget_speed_rpm = 3000.0"
    sc = loads_scene(_scene(_order(2.0, 0.5) + _order(4.0, 0.1, 30.0), extra_crank=run_up))
    ts = np.linspace(0.0, 0.5, 41)
    R = float(sc.pulley("crank").radius)
    a = 3000.0 * 2 * math.pi / 60
    alpha = W * ts + 0.5 * a * ts**2  # the mean rotation (below the target speed)
    got = np.array([float(drive.belt_travel(sc, jnp.float64(x))) / R for x in ts]) - alpha
    want = math.radians(0.5) * np.sin(2 * alpha) + math.radians(0.1) * np.sin(4 * alpha + math.radians(30.0))
    assert np.allclose(got, want, rtol=0, atol=1e-11)


def _trace_csv(tmp_path, cycle_deg=720.0, n=721, orders=((2.0, 0.6, 20.0), (4.0, 0.15, -40.0)), x="angle_deg",
               rows=None):
    alpha = np.linspace(0.0, cycle_deg, n)
    rel = sum(k * math.radians(A) * np.cos(k * np.radians(alpha) + math.radians(p)) for k, A, p in orders)
    rpm = 800.0 * (1.0 + rel)
    body = rows if rows is not None else "".join(f"{a:.17g},{r:.17g}\n" for a, r in zip(alpha, rpm))
    (tmp_path / "crank.csv").write_text(f"{x},speed_rpm\n" + body)
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(_scene('[[fluctuation]]\npulley = "crank"\nfile = "crank.csv"\n'))
    return scene_path


def test_trace_against_crank_angle_gives_its_orders(tmp_path):
    """A measured speed trace (one 720 deg cycle) is read into orders k 360 / 720: the 2nd and 4th
    orders it was made of come back with their angle amplitudes and phases; the rest are ~0."""
    from beltjax.scene import load_scene

    sc = load_scene(_trace_csv(tmp_path))
    by_order = {round(float(x.rate), 6): x for x in sc.fluctuations}
    assert len(sc.fluctuations) == 24 and min(by_order) == 0.5 and all(x.file == "crank.csv" for x in sc.fluctuations)
    for k, A, p in ((2.0, 0.6, 20.0), (4.0, 0.15, -40.0)):
        assert float(by_order[k].amplitude_deg) == pytest.approx(A, rel=1e-3)
        assert float(by_order[k].phase_deg) == pytest.approx(p, abs=0.05)
    others = [float(x.amplitude_deg) for r, x in by_order.items() if r not in (2.0, 4.0)]
    assert max(others) < 1e-3 * 0.6


def test_fixed_frequency_entry_and_forcing_check():
    """A frequency_hz entry is a fixed-frequency harmonic; orders enter the step's resolution check
    at the run's highest speed, so one the step cannot resolve is refused naming its key."""
    sc = loads_scene(_scene('[[fluctuation]]\npulley = "crank"\nfrequency_hz = 40.0\namplitude_deg = 0.2\n'))
    ts = np.linspace(0.0, 0.1, 11)
    assert np.allclose(_fluct(sc, ts), math.radians(0.2) * np.sin(2 * math.pi * 40.0 * ts), atol=1e-12)
    fast = loads_scene(_scene(_order(400.0, 0.01)) + '\n[simulation]\nsolver = "generalized_alpha"\ndt_s = 1e-3\n')
    keys = [f.key for f in excitation.forcing(fast, 0.1)]
    assert "fluctuation[0].order" in keys
    with pytest.raises(BeltjaxError, match=r"fluctuation\[0\]\.order"):
        transient.simulate(fast, 0.1)


def test_amplitude_table_follows_the_speed():
    """An amplitude given against speed is interpolated at the pulley's nominal speed: at a constant
    speed it is that speed's value; in a run-up it changes with the speed (held beyond the table)."""
    table = ('[[fluctuation]]\npulley = "crank"\norder = 2.0\nrpm = [600.0, 1000.0, 3000.0]\n'
             'amplitude_deg = [0.9, 0.5, 0.1]\n')
    ts = np.linspace(0.0, 0.2, 37)
    steady = loads_scene(_scene(table))
    assert np.allclose(_fluct(steady, ts), math.radians(0.7) * np.sin(2 * W * ts), rtol=0, atol=1e-12)  # 800 rpm
    run_up = "acceleration_rpm_per_s = 3000.0\ntarget_speed_rpm = 4000.0"
    sc = loads_scene(_scene(table, extra_crank=run_up))
    ts = np.linspace(0.0, 1.5, 31)
    R = float(sc.pulley("crank").radius)
    a = 3000.0 * 2 * math.pi / 60
    tau = np.minimum(ts, 3200.0 / 3000.0)
    alpha = W * tau + 0.5 * a * tau**2 + 4000.0 * 2 * math.pi / 60 * (ts - tau)
    rpm = 800.0 + 3000.0 * tau
    amp = np.interp(rpm, [600.0, 1000.0, 3000.0], [0.9, 0.5, 0.1])
    got = np.array([float(drive.belt_travel(sc, jnp.float64(x))) / R for x in ts]) - alpha
    assert np.allclose(got, np.radians(amp) * np.sin(2 * alpha), rtol=0, atol=1e-11)


@pytest.mark.parametrize("tables, key", [
    (_order(2.0, 0.5, pulley="alternator"), "fluctuation[0].pulley"),
    ('[[fluctuation]]\npulley = "crank"\norder = 2.0\nfrequency_hz = 3.0\namplitude_deg = 0.1\n', "fluctuation[0].order"),
    (_order(-2.0, 0.5), "fluctuation[0].order"),
    (_order(2.0, -0.5), "fluctuation[0].amplitude_deg"),
    ('[[fluctuation]]\npulley = "crank"\norder = 2.0\namplitude_deg = [0.1, 0.2]\n', "fluctuation[0].amplitude_deg"),
    ('[[fluctuation]]\npulley = "crank"\norder = 2.0\nrpm = [800.0, 900.0]\namplitude_deg = [0.1]\n',
     "fluctuation[0].amplitude_deg"),
    ('[[fluctuation]]\npulley = "crank"\norder = 2.0\nrpm = [800.0, 900.0, 1000.0]\namplitude_deg = [0.1, 0.2]\n',
     "fluctuation[0].amplitude_deg"),
    ('[[fluctuation]]\npulley = "crank"\norder = 2.0\nrpm = [900.0, 800.0]\namplitude_deg = [0.1, 0.2]\n',
     "fluctuation[0].rpm"),
    ('[[fluctuation]]\npulley = "crank"\norder = 2.0\nrpm = [800.0, 900.0]\namplitude_deg = [0.1, -0.2]\n',
     "fluctuation[0].amplitude_deg"),
    ('[[fluctuation]]\npulley = "crank"\norder = 2.0\namplitude_deg = 0.1\nharmonics = 3\n', "fluctuation[0].harmonics"),
])
def test_bad_fluctuation_tables_name_the_key(tables, key):
    with pytest.raises(BeltjaxError) as e:
        loads_scene(_scene(tables))
    assert key in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("rows, x, cause", [
    ("0.0,800.0\n", "angle_deg", "1 sample"),
    ("0.0,800.0\n10.0,801.0\n5.0,800.0\n20.0,799.0\n720.0,800.0\n", "angle_deg", "must increase"),
    ("0.0,800.0\n0.01,801.0\n0.01,800.0\n0.03,799.0\n0.04,800.0\n", "time_s", "must increase"),
    ("0.0,800.0\n0.01,801.0\n0.02,800.0\n0.03,799.0\n0.04,800.0\n0.05,800.0\n", "time_s", None),
])
def test_bad_traces_name_the_file(tmp_path, rows, x, cause):
    from beltjax.scene import load_scene

    path = _trace_csv(tmp_path, rows=rows, x=x)
    if cause is None:  # a good time trace at the pulley's speed: accepted (harmonics limited by its samples)
        path.write_text(path.read_text() + "harmonics = 2\n")
        assert len(load_scene(path).fluctuations) == 2
        return
    with pytest.raises(BeltjaxError) as e:
        load_scene(path)
    assert "fluctuation[0].file" in str(e.value) and cause in str(e.value)


@pytest.mark.parametrize("tables,key", [
    (_order(2.0, 0.5), "fluctuation[0].order"),
    ('[[fluctuation]]\npulley = "crank"\nfrequency_hz = 40.0\namplitude_deg = 0.1\n', "fluctuation[0].frequency_hz"),
])
def test_orders_need_their_effect(tables, key):
    """Without its effect a [[fluctuation]] table is an error naming the key the file gives."""
    with pytest.raises(BeltjaxError, match=re.escape(f'{key}: given but "speed_fluctuation" is not in model.effects')):
        loads_scene(_scene(tables).replace(', "speed_fluctuation"]', "]"))


def test_amplitude_table_interpolation_equals_jnp_interp():
    """The loop-free interpolation of an amplitude table (scene/spec._interp_held) gives jnp.interp's
    values and derivatives in the speed and the table's values, held beyond the ends."""
    import jax

    from beltjax.scene.spec import _interp_held

    xs = jnp.linspace(0.0, 8000.0, 401) + 0.3
    for xp, fp in (([800.0, 1500.0, 3000.0, 6000.0], [0.5, 0.2, 0.1, 0.03]), ([800.0], [0.4]), ([600.0, 900.0], [0.4, 1.0])):
        xp, fp = jnp.asarray(xp), jnp.asarray(fp)
        ours = jax.vmap(lambda x: _interp_held(x, xp, fp))(xs)
        ref = jnp.interp(xs, xp, fp)
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-15)
        d_ours = jax.vmap(jax.grad(lambda x: _interp_held(x, xp, fp)))(xs)
        d_ref = jax.vmap(jax.grad(lambda x: jnp.interp(x, xp, fp)))(xs)
        np.testing.assert_allclose(d_ours, d_ref, rtol=0, atol=1e-15)
        for x in (100.0, 1000.0, 7000.0):
            np.testing.assert_allclose(jax.grad(lambda f: _interp_held(x, xp, f))(fp),
                                       jax.grad(lambda f: jnp.interp(x, xp, f))(fp), rtol=0, atol=1e-15)


def _load_refused(path):
    """The one-line error of a scene that must be refused, with no numpy RuntimeWarning on the way."""
    import warnings

    from beltjax.scene import load_scene

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(BeltjaxError) as e:
            load_scene(path)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("fluctuation[0].")
    return msg


def _cycle(n=73, cycle=720.0, rpm=lambda a: 800.0 + 10.0 * np.sin(np.radians(2 * a)), x=None):
    xs = np.linspace(0.0, cycle, n) if x is None else x
    return "".join(f"{float(a)!r},{float(rpm(a))!r}\n" for a in xs)


@pytest.mark.parametrize("rows, x, phrase, h", [
    # one huge speed sample overflowed the mean: every harmonic 0, RuntimeWarnings, accepted
    (_cycle().replace("\n10.0,", "\n10.0,1e308,", 1).replace(",1e308,", ",1e308\n#", 1), "angle_deg",
     "line 3, column 2 (speed_rpm): must lie in [-1e+06, 1e+06] rpm", 24),
    (_cycle(cycle=7.2e300), "angle_deg", "line 3, column 1 (angle_deg): must lie in [-3600, 3600] deg", 24),
    (_cycle(x=np.linspace(-7200.0, -6480.0, 73)), "angle_deg", "line 2, column 1 (angle_deg): must lie in [-3600, 3600] deg", 24),
    (_cycle(x=np.linspace(-0.1, 0.05, 9), rpm=lambda t: 800.0), "time_s", "line 2, column 1 (time_s): must be >= 0", 4),
    (_cycle(x=np.linspace(0.0, 2e6, 9), rpm=lambda t: 800.0), "time_s", "line 7, column 1 (time_s): must lie in [0, 1e+06] s", 4),
    # derived harmonics in the fields' ranges: a cycle of 10 turns with a wild speed -> amplitude > 360 deg
    (_cycle(n=9, cycle=3600.0, rpm=lambda a: 1e6 if a < 1800.0 else 1.0), "angle_deg",
     "harmonic 1 of its cycle of 3600 deg: amplitude_deg must lie in [0, 360] deg", 4),
    # ... and a time cycle of 4 us -> 250 kHz..1.25 MHz
    (_cycle(n=11, x=np.linspace(0.0, 4e-6, 11), rpm=lambda t: 800.0 + 8.0 * math.sin(2 * math.pi * t / 4e-6)),
     "time_s", "harmonic 5 of its cycle of 4e-06 s: frequency_hz must lie in [0, 1e+06] Hz", 5),
])
def test_trace_values_and_harmonics_in_range(tmp_path, rows, x, phrase, h):
    """Every sample of a trace lies in its column's range (named by line and column), and the
    harmonics read from it in the ranges of a hand-written harmonic; no RuntimeWarning."""
    path = _trace_csv(tmp_path, rows=rows, x=x)
    path.write_text(path.read_text() + f"harmonics = {h}\n")
    msg = _load_refused(path)
    assert msg.startswith("fluctuation[0].file: crank.csv: ") and phrase in msg, msg


@pytest.mark.parametrize("rows, phrase", [
    ("".join(f"{float(v)!r}\n" for a in np.linspace(0.0, 720.0, 73) for v in (a, 800.0)), "line 2: 1 value for the header's 2 columns"),
    ("0.0,800.0\n10.0,800.0,1.0\n20.0,800.0\n720.0,800.0\n", "line 3: 3 values for the header's 2 columns"),
    ("0.0,800.0\n# a comment\n\n10.0,fast\n20.0,800.0\n720.0,800.0\n", "line 5, column 2 (speed_rpm): not a number"),
    ("0.0,800.0\n10.0,800.0\n20.0,-800.0\n720.0,800.0\n", "line 4: speed_rpm must be > 0"),
])
def test_trace_rows_are_checked_one_by_one(tmp_path, rows, phrase):
    """Each row has the header's number of columns (the values are not regrouped), named by line."""
    msg = _load_refused(_trace_csv(tmp_path, rows=rows))
    assert phrase in msg, msg


@pytest.mark.parametrize("name, phrase", [
    ("/etc/passwd", "is an absolute path"),
    ("../outside/crank.csv", "leads out of the scene file's folder through '..'"),
    ("sub/../crank.csv", "through '..'"),
    ("link.csv", "is a link to a file outside the scene file's folder"),
])
def test_trace_file_stays_in_the_scene_folder(tmp_path, name, phrase):
    """A trace file is named relative to the scene file's folder and cannot leave it."""
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "crank.csv").write_text("angle_deg,speed_rpm\n" + _cycle())
    here = tmp_path / "here"
    here.mkdir()
    (here / "link.csv").symlink_to(tmp_path / "outside" / "crank.csv")
    path = _trace_csv(here, rows=_cycle())
    path.write_text(path.read_text().replace('file = "crank.csv"', f'file = "{name}"'))
    msg = _load_refused(path)
    assert msg.startswith(f"fluctuation[0].file: {name} ") and phrase in msg, msg
    (here / "sub").mkdir()
    path.write_text(path.read_text().replace(f'file = "{name}"', 'file = "sub/crank.csv"'))
    (here / "sub" / "crank.csv").write_text("angle_deg,speed_rpm\n" + _cycle())
    from beltjax.scene import load_scene

    assert len(load_scene(path).fluctuations) == 24  # a file in a folder below the scene's is read


@pytest.mark.parametrize("first, shown", [
    ("password=hunter2-this-is-a-secret-line-of-some-other-file", "1 column, not a header line"),
    (",".join(f"secretcolumn{i:03d}" for i in range(20)), "20 columns: secretcolumn000, secretcolumn001"),
])
def test_trace_errors_do_not_quote_the_file(tmp_path, first, shown):
    """A file that is not a trace is refused without quoting its text: at most its header's names,
    when they are words, cut to 60 characters."""
    path = _trace_csv(tmp_path, rows="")
    (tmp_path / "crank.csv").write_text(first + "\nmore secret text\n")
    msg = _load_refused(path)
    assert shown in msg and "hunter2" not in msg and "more secret" not in msg and "secretcolumn004" not in msg, msg
