"""Excitation the step or the output sampling cannot resolve (issue 20, item 5; beltjax.excitation).

A 4990 Hz torque at dt = 2e-4 s used to come out as a false 10 Hz response.  Every forcing of
a scene (torque, span load, speed fluctuation, unbalanced pulleys' rotation at the highest
speed of the run, load windows) is checked against the fixed step (refused at or above its
Nyquist frequency, warned below 20 steps per period) and the output sampling (refused at or
above its Nyquist frequency); an adaptive solver is kept from stepping over a forcing; an
output interval below a fixed step and a run of more than MAX_STEPS steps are refused.

All but one test fail before anything is compiled; the adaptive-pulse test runs the
rotational bench (one compilation).
"""

from __future__ import annotations

import glob

import numpy as np
import pytest

from beltjax import excitation, statics, transient
from beltjax.scene import load_scene, loads_scene

from _scenes import SCENES, scene_text, substitute

T200 = scene_text("two_pulley_T200.toml")
ROT = substitute(T200, ('fidelity = "ancf"', 'fidelity = "rotational"'))
FLUCT = scene_text("sim_two_pulley_fluctuation.toml")


def _torque(freq, amplitude=5.0, extra=""):
    return f'\n[[torque]]\npulley = "alternator"\namplitude_Nm = {amplitude}\nfrequency_hz = {freq}\n{extra}'


def _driven(text, rpm, effects, more=""):
    """The bench with its crank driven at rpm (plus ``more`` crank keys) and the effects listed."""
    return substitute(text, ("driven = false ", "driven = true "), ("speed_rpm = 0.0 ", f"speed_rpm = {rpm}\n{more} "),
                      ('effects = ["transport"]', f"effects = {effects}"))


# Each class of forcing above the step's Nyquist frequency: (scene text, simulate kwargs, key, Hz)
STEP_CASES = {
    "torque": (T200 + _torque(4990.0), dict(dt=2e-4), "torque[0].frequency_hz", "4990 Hz"),
    "span_load": (T200 + '\n[[span_load]]\nspan = "crank-alternator"\nnode = 8\namplitude_N = 1.0\n'
                  "frequency_hz = 3000.0\n", dict(dt=2e-4), "span_load[0].frequency_hz", "3000 Hz"),
    "fluctuation": (_driven(T200, 600.0, '["transport", "speed_fluctuation"]',
                            "fluctuation_amplitude_deg = 0.01\nfluctuation_frequency_hz = 2600.0"),
                    dict(dt=2e-4), "pulley[0].fluctuation_frequency_hz", "2600 Hz"),
    # the alternator turns R_c / R_a = 2.71 times faster than the crank: 56 000 rpm of crank
    # is 2526 Hz of alternator
    "unbalance": (_driven(T200, 56000.0, '["transport", "unbalance"]').replace(
        "inertia = 1.7019e-3        # kg m^2", "inertia = 1.7019e-3\ncm_offset = [1e-5, 0.0]"),
        dict(dt=2e-4), "pulley[1].cm_offset", "2526.22 Hz"),
}


@pytest.mark.parametrize("name", list(STEP_CASES))
def test_forcing_at_or_above_the_step_nyquist_is_refused(name):
    """One line naming the key, the frequency, the step and the false frequency it would
    become (4990 Hz at 5000 steps per second: 10 Hz), refused before any compilation."""
    text, kw, key, hz = STEP_CASES[name]
    with pytest.raises(transient.TransientError) as err:
        transient.simulate(loads_scene(text), 0.1, output_dt=2e-4, **kw)
    msg = str(err.value)
    assert msg.startswith(f"{key}: ") and "\n" not in msg
    assert hz in msg and "Nyquist frequency 2500 Hz of the time step dt = 0.0002 s" in msg
    if name == "torque":
        assert "false 10 Hz excitation" in msg and "dt <= 1e-05 s" in msg


def test_forcing_above_the_output_nyquist_is_refused_naming_the_interval():
    """A 600 Hz torque saved every 1e-3 s would alias to 400 Hz in the outputs: refused with the
    interval needed (below 1/(2 f), and the whole number of steps for a fixed step); the same
    for an adaptive solver; at output_dt = 8e-4 s it is accepted."""
    sc = loads_scene(T200 + _torque(600.0))
    with pytest.raises(transient.TransientError) as err:
        transient.simulate(sc, 0.1, dt=1e-4, output_dt=1e-3)
    msg = str(err.value)
    assert msg.startswith("torque[0].frequency_hz: ") and "Nyquist frequency 500 Hz of the output interval" in msg
    assert "false 400 Hz response" in msg and "below 0.0008333 s (a whole number of steps: 0.0008 s)" in msg
    adaptive = loads_scene(ROT + _torque(600.0))
    with pytest.raises(transient.TransientError, match="below 0.0008333 s; "[:-2]):
        transient.simulate(adaptive, 0.1, output_dt=1e-3)
    assert excitation.check(sc, 0.1, 1e-4, 8e-4, True).refused == []


def test_output_interval_below_a_fixed_step_is_an_error():
    """It used to be raised to the step silently; the key is the one that gave it."""
    with pytest.raises(transient.TransientError, match=r"^output_dt: 5e-05 s is below the time step dt = 0.0001 s"):
        transient.simulate(loads_scene(T200), 0.1, dt=1e-4, output_dt=5e-5)
    sc = loads_scene(T200 + "\n[simulation]\ndt_s = 2e-4\noutput_dt_s = 1e-4\n")
    with pytest.raises(transient.TransientError, match=r"^simulation.output_dt_s: 0.0001 s is below the time step"):
        transient.simulate(sc, 0.1)


def test_a_run_of_too_many_steps_is_refused_with_the_number():
    """Fixed step: t_end / dt > MAX_STEPS (20 million); 2e7 steps exactly are accepted."""
    with pytest.raises(transient.TransientError) as err:
        transient.simulate(loads_scene(T200), 3000.0, dt=1e-4, output_dt=0.01)
    assert str(err.value) == (
        f"t_end: 3000 s needs 30000000 steps of dt = 0.0001 s, more than the limit of {transient.MAX_STEPS} (about a "
        "minute of the rotational model, hours of the hybrid one): shorten the run or raise dt")
    assert transient.MAX_STEPS == 20_000_000


def test_a_load_window_shorter_than_two_steps_is_refused():
    sc = loads_scene(T200 + _torque(0.0, amplitude=0.0, extra="mean_Nm = 5.0\nt_start_s = 0.01\nt_end_s = 0.0101\n"))
    with pytest.raises(transient.TransientError, match=r"^torque\[0\].t_end_s: the torque on alternator acts for "
                                                       r"0.0001 s \(t_start_s to t_end_s\), less than 2 time steps"):
        transient.simulate(sc, 0.1, dt=2e-4)


def test_unbalance_is_checked_at_the_highest_speed_of_the_run():
    """A run-up from 600 rpm at 5000 rpm/s: the alternator's unbalance passes the output
    Nyquist frequency (500 Hz at output_dt = 1e-3 s: 11 080 rpm of crank) after 2.1 s, so a
    3 s run is refused and a 2 s run is not; with a target speed of 10 000 rpm, never."""
    base = _driven(ROT, 600.0, '["transport", "unbalance"]', "acceleration_rpm_per_s = 5000.0").replace(
        "inertia = 1.7019e-3        # kg m^2", "inertia = 1.7019e-3\ncm_offset = [1e-5, 0.0]")
    sc = loads_scene(base)
    assert excitation.check(sc, 2.0, 2e-4, 1e-3, True).refused == []
    refused = excitation.check(sc, 3.0, 2e-4, 1e-3, True).refused
    assert len(refused) == 1 and refused[0].startswith("pulley[1].cm_offset: the unbalance of alternator")
    capped = loads_scene(base.replace("acceleration_rpm_per_s = 5000.0", "acceleration_rpm_per_s = 5000.0\n"
                                      "target_speed_rpm = 10000.0"))
    assert excitation.check(capped, 30.0, 2e-4, 1e-3, True).refused == []


def test_warnings_below_twenty_steps_per_period_and_the_adaptive_largest_step():
    """400 Hz at dt = 2e-4 s is 12.5 steps per period: a warning with the measured error
    (1.0-2.2 % in amplitude); 250 Hz (20 steps) none.  An adaptive solver gets dtmax = a
    quarter period; forcing outside the run, or of zero amplitude, is no forcing."""
    sc = loads_scene(T200 + _torque(400.0) + _torque(250.0))
    res = excitation.check(sc, 1.0, 2e-4, 1e-3, True)
    assert res.refused == [] and res.dtmax is None and [w["frequency_hz"] for w in res.warnings] == [400.0]
    line = excitation.warning(res.warnings[0])
    assert line.startswith("warning: torque[0].frequency_hz: the torque on alternator at 400 Hz has only 12.5 time "
                           "steps") and "off by about 1-2.2 % in amplitude" in line and "dt <= 0.000125 s" in line
    assert transient.run_warnings(dict(excitation_warnings=res.warnings)) == [line]
    assert excitation.check(sc, 1.0, 1e-4, 1e-3, False).dtmax == pytest.approx(0.25 / 400.0)
    quiet = loads_scene(T200 + _torque(4990.0, extra="t_start_s = 2.0\n") + _torque(4990.0, amplitude=0.0))
    assert excitation.forcing(quiet, 1.0) == [] and excitation.check(quiet, 1.0, 2e-4, 1e-3, True).refused == []


def test_a_free_drive_pulley_is_checked_after_the_run():
    """A free drive pulley's speed is known only after the run: the recorded speeds of an
    unbalanced pulley above the output Nyquist frequency give a warning record."""
    sc = loads_scene(ROT.replace('effects = ["transport"]', 'effects = ["transport", "unbalance"]').replace(
        "inertia = 1.7019e-3        # kg m^2", "inertia = 1.7019e-3\ncm_offset = [1e-5, 0.0]"))
    speeds = np.array([[0.0, 0.0], [11000.0, 29800.0], [11200.0, 30300.0]])  # rpm, route order (crank, alternator)
    recs = excitation.after_run(sc, speeds, 2e-4, 1e-3, True)
    assert [r["key"] for r in recs] == ["pulley[1].cm_offset"] and recs[0]["frequency_hz"] == pytest.approx(505.0)
    assert "reached 505 Hz in the run" in excitation.warning(recs[0])
    assert excitation.after_run(sc, speeds[:2], 2e-4, 1e-3, True) == []


def test_shipped_scenes_are_neither_refused_nor_warned():
    """Every scenes/*.toml with its default solver, step and output interval, for 10 s."""
    for path in sorted(glob.glob(str(SCENES / "*.toml"))):
        sc = load_scene(path)
        fixed = transient.default_solver(sc) == "generalized_alpha"
        res = excitation.check(sc, 10.0, transient.default_dt(sc), transient.default_output_dt(sc), fixed)
        assert res.refused == [] and res.warnings == [], path


def test_an_adaptive_solver_does_not_step_over_a_short_pulse():
    """Rotational bench at rest, Dopri8: a 0.2 ms torque pulse of 10 N m on the alternator at
    t = 2.3 s.  From a quiet drive the controller's steps grow to ~10 ms and used to step over
    the pulse (the drive stayed at rest); the window's edges are now jump times.  After the
    pulse the free drive's momentum along its rigid turning, p = sum J_i w_i / R_i (J_i with
    the belt wrapped on pulley i), equals the impulse over R_a, 2e-3 N m s / R_a, within 1e-6,
    as after a 2 ms pulse of 1 N m."""
    inst = statics.install(loads_scene(ROT))
    for dur, moment in ((2e-4, 10.0), (2e-3, 1.0)):
        sc = loads_scene(ROT + f'\n[[torque]]\npulley = "alternator"\nmean_Nm = {moment}\nt_start_s = 2.3\n'
                               f"t_end_s = {2.3 + dur}\n")
        res = transient.simulate(sc, 3.0)
        assert res.meta["solver"] == "dopri8"
        w = res.channels["pulley_speeds_rpm"] * np.pi / 30  # rad/s
        assert np.all(np.abs(w[res.t < 2.29]) < 1e-4)  # at rest before it (round-off drift 1e-7 rad/s)
        p = 0.0
        for i, name in enumerate(sc.route.order):
            pl = sc.pulley(name)
            R = float(pl.radius)
            J = float(pl.inertia) + float(sc.belt.rhoA * inst.radii[i] * inst.wrap[i] / inst.stretch) * R**2
            p = p + J * w[:, i] / R
        after = p[res.t > 2.31]
        R_a = float(sc.pulley("alternator").radius)
        print(f"\n  {dur * 1e3:g} ms pulse: momentum {after.mean():.6e} kg m/s (impulse / R_a {2e-3 / R_a:.6e}), "
              f"spread {np.ptp(after):.1e}")
        np.testing.assert_allclose(np.abs(after), 2e-3 / R_a, rtol=1e-6)
