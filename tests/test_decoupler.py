"""The overrunning alternator decoupler ([[decoupler]], beltjax.drive.couplings): a rotor of its
own joined to its pulley by a spring through a one-way clutch."""

from __future__ import annotations

import math
import pathlib

import jax
import numpy as np
import pytest

from beltjax import drive, drive_modal, transient
from beltjax.errors import BeltjaxError
from beltjax.scene import loads_scene

from _scenes import mechanical_energy

ROOT = pathlib.Path(__file__).resolve().parents[1]
FEAD = (ROOT / "scenes" / "fead_8pulley.toml").read_text()
J_ROTOR = 6e-3  # kg m^2


def _with_decoupler(k: float, text: str = FEAD, pulley: str = "alternator") -> str:
    return text + f'\n[[decoupler]]\npulley = "{pulley}"\nrotor_inertia = {J_ROTOR}\nstiffness = {k}\n'


def _with_alternator_inertia(text: str, J: float) -> str:
    head, block = text.split('name = "alternator"', 1)
    before, after = block.split("inertia =", 1)
    return head + 'name = "alternator"' + before + f"inertia = {J!r}" + after[after.index("\n"):]


def test_a_stiff_locked_decoupler_is_the_pulley_with_the_rotors_inertia():
    """With a very stiff spring (engaged under the alternator's load) the drive's modes about its
    operating point are those of one alternator of pulley + rotor inertia, plus the spring's own
    mode far above; the span tensions are the same, the spring wound up by the load over its
    stiffness."""
    J = float(loads_scene(FEAD).pulley("alternator").inertia)
    merged = loads_scene(_with_alternator_inertia(FEAD, J + J_ROTOR))
    assert float(merged.pulley("alternator").inertia) == pytest.approx(J + J_ROTOR)
    k = 1e8
    dec = loads_scene(_with_decoupler(k))

    @jax.jit
    def state(sc):  # the operating point and the modes about it (one compiled call per structure)
        m = drive_modal.at_speed(sc, drive.belt_speed(sc))
        return m, drive.span_tensions(drive.full_coordinates(m.qi, sc, m.inst), sc, m.inst)

    (mm, Tm), (md, Td) = state(drive.canonical(merged)), state(drive.canonical(dec))
    fm, fd = np.asarray(mm.freqs), np.asarray(md.freqs)
    n = len(fm)
    assert np.allclose(fd[:n], fm, rtol=1e-5)
    assert fd[n] > 5 * fm[-1]  # the decoupler spring's own mode
    assert np.allclose(Td, Tm, rtol=1e-9)
    sd = md
    # the rotor lags the pulley by the load over the stiffness (the load acts on the rotor)
    load = sum(float(t.mean_Nm) for t in dec.torques if t.pulley == "alternator")
    i = list(dec.route.order).index("alternator")
    phis, _ = drive.angles_and_arm(sd.qi, dec, sd.inst)
    psi = drive.rotor_angles(sd.qi, dec)
    windup = dec.route.senses[i] * (float(phis[i]) - float(psi[0]))
    assert windup == pytest.approx(abs(load) / k, rel=1e-6)


@pytest.fixture(scope="module")
def overrun():
    """The eight-pulley drive at idle with a strong 2nd order (1.5 deg) and a soft decoupler:
    the alternator pulley decelerates faster than its rotor can, 0.3 s."""
    text = _with_decoupler(30.0, FEAD.replace("amplitude_deg = [0.5,", "amplitude_deg = [1.5,", 1))
    sc = loads_scene(text)
    return sc, transient.simulate(sc, 0.3)


def test_the_clutch_overruns_and_the_rotor_coasts(overrun):
    """The spring only drives the rotor (its moment never pulls it back); where the clutch is
    open the rotor coasts under its own load alone, d(omega)/dt = M_load / J_rotor."""
    sc, res = overrun
    m = res.channels["decoupler_moments_Nm"][:, 0]
    assert m.min() >= 0.0
    open_ = m == 0.0
    assert 0.1 < open_[res.t > 0.1].mean() < 0.9  # it opens and closes every cycle
    w = res.channels["rotor_speeds_rpm"][:, 0] * 2 * math.pi / 60
    dt = res.t[1] - res.t[0]
    acc = np.gradient(w, dt)
    inner = open_ & np.roll(open_, 1) & np.roll(open_, -1) & np.roll(open_, 2) & np.roll(open_, -2)
    load = sum(float(t.mean_Nm) for t in sc.torques if t.pulley == "alternator")
    assert inner.sum() > 20
    assert np.allclose(acc[inner], load / J_ROTOR, rtol=1e-3)
    # the rotor's speed swings less than its pulley's
    i = list(sc.route.order).index("alternator")
    late = res.t > 0.1
    assert np.ptp(w[late]) < np.ptp(res.channels["pulley_speeds_rpm"][late, i] * 2 * math.pi / 60)


@pytest.mark.parametrize("table, key", [
    ('pulley = "crank"\nrotor_inertia = 1e-3\nstiffness = 30.0', "decoupler[0].pulley"),
    ('pulley = "tensioner"\nrotor_inertia = 1e-3\nstiffness = 30.0', "decoupler[0].pulley"),
    ('pulley = "alternator"\nrotor_inertia = 1e-3\nstiffness = -30.0', "decoupler[0].stiffness"),
    ('pulley = "alternator"\nrotor_inertia = 0.0\nstiffness = 30.0', "decoupler[0].rotor_inertia"),
])
def test_bad_decouplers_name_the_key(table, key):
    with pytest.raises(BeltjaxError) as e:
        loads_scene(FEAD + "\n[[decoupler]]\n" + table + "\n")
    assert key in str(e.value) and "\n" not in str(e.value)


def test_two_decouplers_on_one_pulley_are_refused():
    with pytest.raises(BeltjaxError, match=r"decoupler\[1\]\.pulley"):
        loads_scene(_with_decoupler(30.0, _with_decoupler(30.0)))


def test_decoupler_parameters_are_paths():
    """The spring rate and the rotor inertia are parameters of sweeps, fits and optimisation."""
    from beltjax import parameters

    sc = loads_scene(_with_decoupler(30.0))
    assert {"decoupler.alternator.stiffness", "decoupler.alternator.rotor_inertia"} <= set(parameters.paths(sc))
    sc2 = parameters.set_values(sc, {"decoupler.alternator.stiffness": 45.0})
    assert float(sc2.decouplers[0].stiffness) == 45.0
    with pytest.raises(parameters.ParameterError, match="decoupler.alternator.stiffness"):
        parameters.set_values(sc, {"decoupler.alternator.stiffness": -1.0})


def test_energy_is_kept_through_the_clutch():
    """The tensioner bench (rotational, crank held, no damping) with a decoupler on the
    alternator and a constant 0.5 N m on its rotor, released from a 2 deg turn of the alternator
    pulley about the operating point: the clutch engages and overruns in turn, and the mechanical
    energy (kinetic, bars, tensioner spring, the decoupler spring's k max(w, 0)^2 / 2, the load's
    -M psi) stays within 1e-4 of the energy put in (Dopri8, rtol 1e-9): the one-way law is
    conservative."""
    import jax.numpy as jnp

    from beltjax import statics

    text = (ROOT / "scenes" / "sim_tensioner_installation.toml").read_text()
    for old, new in (("CA = 3.33 ", "# CA"), ("damping = 0.1 ", "# damping"),
                     ('effects = ["belt_damping", "tensioner_damping"]', "effects = []"),
                     ("arm_angle_deg = 47.637131 ", "# arm_angle_deg"),
                     ("rotation_deg = { tensioner = 21.289520, alternator = -4.181391 }",
                      "rotation_deg = { alternator = 2.0 }"),
                     ('solver = "generalized_alpha"', 'solver = "dopri8"\nrtol = 1e-9\natol = 1e-12'),
                     ("rho_inf = 1.0", "# (generalized-alpha's)")):
        assert old in text
        text = text.replace(old, new, 1)
    text += ('\n[[decoupler]]\npulley = "alternator"\nrotor_inertia = 2e-3\nstiffness = 50.0\n'
             '\n[[torque]]\npulley = "alternator"\nmean_Nm = 0.5\n')  # on the rotor: a constant, conservative load
    sc = loads_scene(text)
    res = transient.simulate(sc, 0.4)
    m = res.channels["decoupler_moments_Nm"][:, 0]
    assert (m == 0).any() and (m > 0).any()  # it overruns and engages
    st = statics.analyse_statics(sc)  # the operating point under the load
    c = drive.canonical(sc)
    inst, n, d = st.inst, drive.n_independent(c), c.decouplers[0]
    i = list(c.route.order).index("alternator")

    def decoupler_and_load(qi, scene):  # the decoupler spring's k max(w, 0)^2 / 2 and the rotor load's -M psi
        phis, _ = drive.angles_and_arm(qi, scene, inst)
        psi = drive.rotor_angles(qi, scene)[0]
        w = scene.route.senses[i] * (phis[i] - psi)
        return 0.5 * d.stiffness * jnp.maximum(w, 0.0) ** 2 - 0.5 * psi

    energy = mechanical_energy(c, inst, decoupler_and_load)
    E = np.asarray(energy(jnp.asarray(res.y)))
    E0 = float(energy(jnp.concatenate([jnp.asarray(st.qi), jnp.zeros(n)])[None])[0])
    put_in = E[0] - E0
    drift = np.max(np.abs(E - E[0])) / put_in
    print(f"\n  decoupler: {put_in:.4g} J put in, energy kept to {drift:.1e} of it; clutch open "
          f"{np.mean(m == 0):.0%} of the samples")
    assert put_in > 0
    assert drift < 1e-4


def test_statics_reports_the_wind_up():
    """statics.json's operating point gives each decoupler's wind-up (load / stiffness) and moment."""
    from beltjax.static_state import analyse_statics

    res = analyse_statics(loads_scene(_with_decoupler(5.0)), with_unloaded=False)
    load = sum(float(t.mean_Nm) for t in loads_scene(FEAD).torques if t.pulley == "alternator")
    d = res.to_json()["decouplers"]["alternator"]
    assert d["moment_Nm"] == pytest.approx(abs(load), rel=1e-9)
    assert d["windup_deg"] == pytest.approx(math.degrees(abs(load) / 5.0), rel=1e-9)


def test_an_unloaded_decoupler_rests_engaged_and_a_driving_load_is_refused():
    """A decoupler on an idler (no load) sits at zero wind-up: statics takes the spring engaged on
    both sides of w = 0, where the overrunning range left the rotor's angle without an equilibrium
    (Newton stalled at NaN); the drive's tensions are those without it.  A mean load that drives a
    decoupled pulley's rotor ahead has no steady state: a one-line error naming the decoupler."""
    from beltjax.static_state import StaticsError, analyse_statics

    plain = analyse_statics(loads_scene(FEAD), with_unloaded=False)
    res = analyse_statics(loads_scene(_with_decoupler(5.0, pulley="idler_top")), with_unloaded=False)
    d = res.to_json()["decouplers"]["idler_top"]
    assert abs(d["windup_deg"]) < 1e-6 and abs(d["moment_Nm"]) < 1e-6
    np.testing.assert_allclose(res.span_tensions_N, plain.span_tensions_N, rtol=1e-9)
    driving = _with_decoupler(5.0).replace('pulley = "alternator"\nmean_Nm = ', 'pulley = "alternator"\nmean_Nm = -')
    assert driving != _with_decoupler(5.0)
    with pytest.raises(StaticsError, match="drives its decoupler's rotor ahead") as e:
        analyse_statics(loads_scene(driving), with_unloaded=False)
    assert e.value.key == "decoupler[0].pulley"


def test_a_sweep_case_whose_load_drives_the_rotor_ahead_fails():
    """The batched statics of a sweep takes the same engaged spring, so a load that drives the
    rotor ahead converges there at a negative wind-up: the case fails as decoupler_overrun (NaN),
    not ok, while the same drive loaded against its travel is ok."""
    from beltjax import sweep

    driving = _with_decoupler(5.0).replace('pulley = "alternator"\nmean_Nm = ', 'pulley = "alternator"\nmean_Nm = -')
    k = {"decoupler.alternator.stiffness": np.array([5.0, 8.0])}
    bad = sweep.evaluate(loads_scene(driving), k, ("statics",))
    good = sweep.evaluate(loads_scene(_with_decoupler(5.0)), k, ("statics",))
    assert list(bad["status"]) == ["decoupler_overrun"] * 2 and np.all(np.isnan(bad["span_tensions_N"]))
    assert list(good["status"]) == ["ok"] * 2
