"""The crank isolator ([isolator], beltjax.drive.couplings): the driven crank's rim on a spring and
damper to its prescribed hub."""

from __future__ import annotations

import math
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import drive, drive_modal, transient
from beltjax.errors import BeltjaxError
from beltjax.scene import loads_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]
F_HZ, A_DEG = 20.0, 0.5  # the hub's fluctuation


def _scene(extra: str = "") -> str:
    """The two-pulley bench, rotational, crank driven at 600 rpm with a 20 Hz fluctuation of its
    hub, on an isolator."""
    text = (ROOT / "scenes" / "two_pulley_T200.toml").read_text()
    text = text.replace("driven = false             # free to turn", "driven = true  # free to turn", 1)
    text = text.replace("speed_rpm = 0.0            # static bench",
                        f"speed_rpm = 600.0\nfluctuation_amplitude_deg = {A_DEG}\nfluctuation_frequency_hz = {F_HZ}", 1)
    text = text.replace('fidelity = "ancf"', 'fidelity = "rotational"', 1)
    text = text.replace('effects = ["transport"]', 'effects = ["transport", "speed_fluctuation"]', 1)
    return text + extra


ISOLATOR = '\n[isolator]\npulley = "crank"\nstiffness = 400.0\ndamping = 0.3\n'


def test_the_response_is_the_two_degree_of_freedom_transmissibility():
    """The rim (on the isolator) and the alternator (on the belt) are a two-degree-of-freedom
    system driven by the hub's motion: the steady response of the transient at the hub's
    frequency equals (K - w^2 M + i w C)^-1 w^2 A M r, with M, K the drive's linearisation about
    its operating point, C the isolator's damping and r the nominal rolling per radian of hub,
    to 1 % in amplitude and 1 deg in phase."""
    sc = loads_scene(_scene(ISOLATOR))
    assert drive.n_independent(sc) == 2 and drive_modal.n_rigid_modes(sc) == 0
    res = transient.simulate(sc, 1.5)
    t = res.t
    late = t > 1.0  # ten hub periods after the free vibration has died out (damping ratios >= 0.02)
    w = 2 * math.pi * F_HZ
    rot = np.radians(res.channels["pulley_rotations_deg"][late])  # (nt, 2): crank rim, alternator
    tone = lambda x: 2 * np.mean(x * np.exp(-1j * w * t[late]))  # noqa: E731  complex amplitude of sin/cos

    c = drive.canonical(sc)
    st = transient.initial_state(sc)
    inst, qi = st[0], st[1]
    speed = drive.belt_speed(c)
    M, G, K = drive_modal.linearise(qi, c, inst, speed)
    d = drive.drive_pulley(c)
    r = drive_modal.rigid_mode(c, inst) * (c.route.senses[d] * float(inst.radii[d]))
    C = jnp.zeros_like(M).at[drive.travel_coordinate(c), drive.travel_coordinate(c)].set(c.isolator.damping)
    A = c.route.senses[d] * math.radians(A_DEG)  # the hub's fluctuation, CCW: the belt's travel turns with s
    # the hub's angle A sin(w t) = Im(A e^{i w t}): phasors of sin are taken as -i times the cos tone
    phasor = np.linalg.solve(np.asarray(K - w**2 * M + 1j * w * (C + G)), w**2 * A * np.asarray(M @ r))
    for k in range(2):
        got = tone(rot[:, k])  # = X e^{i phase} for x = Re(X e^{i w t})
        want = -1j * phasor[k]  # x = Im(P e^{i w t}) = Re(-i P e^{i w t})
        print(f"\n  isolator, {['rim', 'alternator'][k]}: amplitude {abs(got):.4e} rad against {abs(want):.4e} "
              f"({abs(got) / abs(want) - 1:+.1e}), phase {np.degrees(np.angle(got / want)):+.2f} deg")
        assert abs(got) == pytest.approx(abs(want), rel=1e-2)
        assert abs(np.angle(got / want)) < math.radians(1.0)
    # the isolator's moment swings about the drive torque
    m = res.channels["isolator_moment_Nm"][late]
    assert abs(np.mean(m)) < 0.05 * np.ptp(m) + 1e-3


def test_a_stiff_isolator_is_the_rigid_crank():
    """A very stiff isolator adds a mode far above and leaves the others of the driven crank."""
    rigid = drive_modal.analyse_modes(loads_scene(_scene()))
    stiff = drive_modal.analyse_modes(loads_scene(_scene('\n[isolator]\npulley = "crank"\nstiffness = 1e8\n')))
    f0, f1 = rigid.frequencies_hz, stiff.frequencies_hz
    assert np.allclose(f1[: len(f0)], f0, rtol=1e-4)
    assert f1[len(f0)] > 20 * f0[-1]


@pytest.mark.parametrize("table, key", [
    ('[isolator]\npulley = "alternator"\nstiffness = 400.0', "isolator.pulley"),
    ('[isolator]\npulley = "crank"\nstiffness = -400.0', "isolator.stiffness"),
    ('[isolator]\npulley = "crank"\nstiffness = 400.0\ndamping = -1.0', "isolator.damping"),
])
def test_bad_isolators_name_the_key(table, key):
    with pytest.raises(BeltjaxError) as e:
        loads_scene(_scene("\n" + table + "\n"))
    assert key in str(e.value) and "\n" not in str(e.value)


def test_isolator_parameters_are_paths():
    from beltjax import parameters

    sc = loads_scene(_scene(ISOLATOR))
    assert {"isolator.stiffness", "isolator.damping"} <= set(parameters.paths(sc))
    assert float(parameters.set_values(sc, {"isolator.stiffness": 500.0}).isolator.stiffness) == 500.0


def test_an_isolator_too_soft_for_its_drive_torque_is_refused():
    """A spring that would wind up by more than half a turn to carry the drive torque is no
    isolator: the operating point is refused naming isolator.stiffness (a fuzzing pass found
    1e-6 N m/rad wound up by 1e9 deg, with no flag); one that carries it within a few degrees is
    the operating point."""
    from beltjax import statics

    load = '\n[[torque]]\npulley = "alternator"\nmean_Nm = 5.0\n'
    with pytest.raises(BeltjaxError, match="winds up by") as e:
        statics.analyse_statics(loads_scene(_scene(load + '\n[isolator]\npulley = "crank"\nstiffness = 1.0\n')))
    assert e.value.key == "isolator.stiffness" and "at least" in str(e.value)
    r = statics.analyse_statics(loads_scene(_scene(load + ISOLATOR)))
    assert abs(r.drive_torque_Nm) > 10.0
