"""Whole-drive transients (beltjax.transient.simulate) against the thesis' simulations (ch. 7).

Thesis numbers are read from ../shared/reference/thesis_reference.json (the ``ref``
fixture) or, where the thesis prints them only in the text of a simulation section, from
the example scenes ``scenes/sim_*.toml`` (each cites its section).  The tests run those
scenes, or variants of them made by replacing text (every replaced string is checked to
be there).

Model facts behind the tolerances
---------------------------------
* The spans follow a Green-Lagrange axial law, T = EA (lam^2 - 1) lam / 2, whose tangent
  stiffness EA (3 lam^2 - 1) / 2 is 1.6 % above EA at the bench's 600 N; the thesis'
  rotational model uses the linear k = EA / L (eq. 4.13).  The pulleys also carry the belt
  wrapped on them.  Our torsional modes therefore sit 1.3 % (free-free) and 1.9 % (crank
  prescribed) above the thesis' 96.7 and 81.8 Hz; the thesis' own printed numbers are not
  consistent with one stiffness either (see test_release_initial_span_forces).  Against the
  thesis we allow 2.5 %; against the package's own linear modal analysis the comparison is
  tight, after correcting for the integrator's known period error.
* The integrator is generalized-alpha at rho_inf = 1, i.e. the implicit midpoint rule: it
  turns a linear oscillator of angular frequency w by exactly 2 atan(w dt / 2) per step
  (tests/test_transient.py), so a transient shows f_dt = atan(pi f dt) / (pi dt) for a mode
  of frequency f (0.13 % low at 98 Hz and dt = 2e-4 s).

Cost (2 shared CPU cores): about 4 minutes for the file, almost all of it compiling.  Six
rotational structures (9-14 s to compile the integrator, then ~20 us a step, 50 000 steps in
1 s) and three hybrid ones (the two-pulley bench with 6 ANCF elements per span: 17 s, then
~0.3 ms a step; the tensioner bench with 4: 35 s, then ~0.1 ms a step); runs of
one structure differ only in numbers, the [initial] table and the span-load timing, and use
one chunk length (``CHUNK``) and, within a fixture, one duration, so that they share the
compiled integrator and output function.  (A new [initial] table still recompiles the
statics that start the run, 3-9 s: transient.initial_state hands the jitted statics the
scene with its [initial], [simulation] and load tables, which are static fields.)
"""

from __future__ import annotations

import logging
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import drive, drive_modal, signals, span, statics, transient
from beltjax.scene import load_scene, loads_scene

from _scenes import SCENES, scene_text, substitute

#: one chunk length for every run, so that runs of one structure share the compiled integrator
CHUNK = 0.5


# --------------------------------------------------------------------------- helpers


def _simulate(scene, t_end, label):
    t0 = time.perf_counter()
    res = transient.simulate(scene, t_end, chunk_s=CHUNK)
    print(f"\n  {label}: {res.meta['steps']} steps, {time.perf_counter() - t0:.1f} s wall "
          f"(first chunk {res.meta['first_chunk_s']:.1f} s)")
    return res


def _complex_tone(t, x, f):
    """Complex amplitude (with its phase) of the sine of frequency f (Hz) in x(t):
    Hann-windowed single-frequency DFT.

    Exact for a pure tone at f (any f, not only bin frequencies) up to the leakage of its
    mirror image at -f and of other lines, small when they lie several bins (1 / duration)
    away."""
    w = np.hanning(t.size)
    return 2 * np.sum(w * (x - x.mean()) * np.exp(-2j * np.pi * f * t)) / np.sum(w)


def _tone(t, x, f):
    """Amplitude of the sine of frequency f (Hz) in x(t) (see :func:`_complex_tone`)."""
    return abs(_complex_tone(t, x, f))


def _rotating(t, z, f):
    """Amplitude of the component of the complex signal z = Fx + i Fy that turns at f (Hz;
    positive counter-clockwise)."""
    return abs(_complex_tone(t, z, f)) / 2


def _midpoint(f, dt):
    """Frequency (Hz) that the implicit midpoint rule shows for a mode of frequency f at step dt."""
    return math.atan(math.pi * f * dt) / (math.pi * dt)


def _dominant(t, x, fmin=5.0):
    return signals.dominant_frequencies(t, x, count=1, fmin=fmin)[0][0]


def _window(res, t0, t1):
    return (res.t >= t0 - 1e-9) & (res.t < t1 - 1e-9)


def _col(res, channel, name):
    return res.channels[channel][:, res.columns[channel].index(name)]


def _belt_CA(ref):
    """Belt damping CA (N s) from the tensile tests' complex modulus of the bench belt: CA =
    |Im G(f)| L / (2 pi f) (Kelvin-Voigt equivalent, thesis eqs. 6.1 and 6.7), at the free-free
    torsional frequency of the thesis, where it adopted EA (bench belt B, EA near 97 Hz)."""
    tt = ref["tensile_test_complex_modulus"]
    b = tt["belts"][tt["bench_belt"][0]]
    f = ref["two_pulley_bench"]["rotational_model_checks"]["free_free_torsional_frequency_hz"]
    c = lambda p: complex(*p)  # noqa: E731
    G = c(b["a1"]) * f ** c(b["b1"]) + c(b["a2"]) * f ** c(b["b2"])  # N/mm over L mm
    return abs(G.imag) * b["L_m"] * 1000.0 / (2 * math.pi * f)


def _tangent_EA(scene, lam):
    """Tangent axial stiffness dT/d lam of the Green-Lagrange law at stretch lam (N)."""
    return float(scene.belt.EA) * (3 * lam**2 - 1) / 2


def _energy_fn(scene, inst):
    """Mechanical energy (J) of a state y = (q_i, q_i') at rest (no belt speed), in the
    transient's kinematic map: kinetic (bodies, and the spans' 1/2 int rhoA |r_t + c r_x|^2 dx
    with c the drive pulley's rim speed: a free drive pulley's belt travels with it), elastic
    energy of the spans (bars or ANCF), weight (with the potential of the constant moments that
    take the spans' slides out of it, drive.belt_weight_slide_moments), tensioner spring."""
    scene = drive.canonical(scene)
    n = drive.n_independent(scene)
    ns = drive.n_span_coordinates(scene)
    gravity = scene.model.has("gravity")
    L0 = drive.element_length(scene, inst)
    EA, rhoA = scene.belt.EA, scene.belt.rhoA
    mb = drive.body_masses(scene, inst)

    def energy(y):
        qi, qd = y[:n], y[n:]
        q, v = jax.jvp(lambda x: drive.full_coordinates(x, scene, inst, t=0.0), (qi,), (qd,))
        E, B = drive.split_full(q, scene)
        K = 0.5 * jnp.sum(mb * v[ns:] ** 2)
        if drive.flexible(scene):
            N = scene.model.elements_per_span
            idx = span.element_index(N)
            Ed = v[:ns].reshape(E.shape)
            c = drive.transient_transport_speed(scene, inst, v, 0.0)[0]
            K = K + sum(span.span_kinetic_energy(E[s], Ed[s], c, rhoA, L0[s], idx) for s in range(E.shape[0]))
            V = sum(drive.span_potential(E[s], s, scene, inst) for s in range(E.shape[0]))
            if gravity:
                phi, _ = drive.angles_and_arm(qi, scene, inst)
                V = V - jnp.sum(drive.belt_weight_slide_moments(scene, inst, True) * phi)
        else:
            V = sum(drive.span_potential(E[s], s, scene, inst) for s in range(E.shape[0]))
        if gravity:
            V = V - drive.GRAVITY[1] * jnp.sum(mb.reshape(-1, 3)[:, 0] * B[:, 1])
        if scene.tensioner is not None:
            _, theta = drive.angles_and_arm(qi, scene, inst)
            t = scene.tensioner
            V = V + 0.5 * t.spring_stiffness * (theta - jnp.deg2rad(t.spring_preload_deg)) ** 2
        return K + V

    return jax.jit(jax.vmap(energy))


def test_scene_damping_parameters_come_from_the_complex_modulus(ref):
    """Every example scene with belt damping uses the CA derived from the tensile tests."""
    CA = _belt_CA(ref)
    assert 3.2 < CA < 3.5  # loss factor 0.018 at 96.7 Hz: |Im G| / Re G
    checked = 0
    for path in sorted(SCENES.glob("sim_*.toml")):
        sc = load_scene(path)
        if sc.model.has("belt_damping"):
            assert abs(float(sc.belt.CA) / CA - 1) < 0.01, (path.name, float(sc.belt.CA), CA)
            checked += 1
    assert checked >= 5


# =========================================================================== 7.1.1.2: release


@pytest.fixture(scope="module")
def release():
    """Sim 1 (thesis 7.1.1.2): the alternator released from 2 deg, undamped and damped, 10 s each."""
    damped = load_scene(SCENES / "sim_two_pulley_release.toml")
    text = scene_text("sim_two_pulley_release.toml")
    undamped = loads_scene(substitute(text, ("CA = 3.33 ", "CA = 0.0 ")))
    out = dict(damped_scene=damped, undamped_scene=undamped)
    out["undamped"] = _simulate(undamped, 10.0, "release, undamped")
    out["damped"] = _simulate(damped, 10.0, "release, damped")
    out["modes"] = drive_modal.analyse_modes(undamped)
    out["statics"] = out["modes"].statics
    return out


def test_release_initial_span_forces(ref, release):
    """t = 0: the 2 deg alternator rotation stretches the upper span and relaxes the lower one.

    Thesis: T1 = 813 N, T2 = 389 N, i.e. +-212 N about 601 N.  The linear law of the thesis
    with this geometry (k = EA / L0, the alternator rim moving R_a theta = 1.309 mm) gives
    +-215.1 N (the printed pair implies a span 1.5 % longer than the printed geometry's);
    our Green-Lagrange tangent stiffness adds 1.6 %: +-219.75 N, 3.7 % above the thesis.  The
    half-difference has no quadratic term (it is odd in the rotation), so it must equal the
    tangent-stiffness prediction to the cubic term (1e-6): 1e-4 allowed; the thesis: 4.5 %.
    """
    checks = ref["two_pulley_bench"]["rotational_model_checks"]
    T1_thesis, T2_thesis = checks["span_forces_at_t0_N"]
    res, sc, st = release["undamped"], release["undamped_scene"], release["statics"]
    upper = _col(res, "span_forces_N", "alternator-crank")[0]
    lower = _col(res, "span_forces_N", "crank-alternator")[0]
    lam = st.stretch
    L0 = st.span_lengths_m / lam  # unstretched span lengths (m)
    slide = float(sc.pulley("alternator").radius) * math.radians(checks["initial_alternator_rotation_deg"])
    predicted = _tangent_EA(sc, lam) * slide / L0[0]
    half = (upper - lower) / 2
    print(f"\n  t = 0: upper {upper:.1f} N, lower {lower:.1f} N (thesis {T1_thesis}, {T2_thesis}); "
          f"+-{half:.2f} N vs Green-Lagrange {predicted:.2f} N")
    assert upper > float(sc.belt.static_tension) > lower
    assert abs(half / predicted - 1) < 1e-4
    assert abs(half / ((T1_thesis - T2_thesis) / 2) - 1) < 0.045
    # the mean stays at the installation tension (quadratic term: 3 EA lam delta^2 / 2 = 0.6 N)
    assert abs((upper + lower) / 2 - float(sc.belt.static_tension)) < 1.0
    assert abs((upper + lower) / (T1_thesis + T2_thesis) - 1) < 0.005


def test_release_torsional_frequency(ref, release):
    """Undamped, 10 s: the pulleys oscillate in phase opposition at the torsional mode.

    * against the package's linear modal analysis (after the midpoint rule's period error):
      1e-4 (0.01 Hz, 0.1 bin of the 10 s record, 5x the peak interpolation's error; the
      2 deg amplitude shifts the frequency by ~1e-6 through the Green-Lagrange cubic term);
      measured 1.4e-5;
    * against a hand formula, two inertias on massless Green-Lagrange springs (tangent
      stiffness over the unstretched span length) with the wrapped belt on the pulleys: the
      rotational model is exactly that, 1e-4 allowed (measured < 1e-6);
    * against the thesis' 96.7 Hz: 2.5 % (module docstring).
    """
    thesis = ref["two_pulley_bench"]["rotational_model_checks"]["free_free_torsional_frequency_hz"]
    res, sc, st = release["undamped"], release["undamped_scene"], release["statics"]
    modes = release["modes"]
    assert modes.labels == ["rigid body", "1st rotational (alternator, crank)"]
    f_modal = modes.frequencies_hz[1]
    dt = res.meta["dt_s"]
    f_sim = _dominant(res.t, _col(res, "pulley_speeds_rpm", "alternator"))
    # the crank swings in opposition at the same frequency
    assert abs(_dominant(res.t, _col(res, "pulley_speeds_rpm", "crank")) / f_sim - 1) < 1e-4
    # hand formula: omega^2 = sum_s k_s * sum_i R_i^2 / J_i
    inst, lam = st.inst, st.stretch
    k = _tangent_EA(sc, lam) / (st.span_lengths_m / lam)
    J = {}
    for i, name in enumerate(sc.route.order):
        p = sc.pulley(name)
        m_arc = float(sc.belt.rhoA * inst.radii[i] * inst.wrap[i]) / lam  # belt wrapped on it (kg)
        J[name] = (float(p.inertia) + m_arc * float(p.radius) ** 2, float(p.radius))
    f_hand = math.sqrt(k.sum() * sum(R**2 / Ji for Ji, R in J.values())) / (2 * math.pi)
    print(f"\n  torsional mode: transient {f_sim:.4f} Hz, modal {f_modal:.4f} Hz "
          f"(midpoint {_midpoint(f_modal, dt):.4f}), hand {f_hand:.4f} Hz, thesis {thesis} Hz")
    assert abs(f_sim / _midpoint(f_modal, dt) - 1) < 1e-4
    assert abs(f_modal / f_hand - 1) < 1e-4
    assert abs(f_modal / thesis - 1) < 0.025


def test_release_undamped_energy_is_conserved(release):
    """10 s (980 periods) without damping: the mechanical energy stays within 1e-7 of the
    vibration energy put in by the initial rotation (both spans stretched by R_a theta,
    1/2 sum k_s (R_a theta)^2 = 0.29 J).  The midpoint rule conserves quadratic energies
    exactly; the Green-Lagrange bar energy is quartic, so the error is O(dt^2) and bounded
    (measured 3.5e-9), with no drift between the first and last second (measured 1e-11;
    1e-9 allowed)."""
    res, sc, st = release["undamped"], release["undamped_scene"], release["statics"]
    energy = _energy_fn(sc, st.inst)
    E = np.asarray(energy(jnp.asarray(res.y)))
    E_static = float(energy(jnp.concatenate([jnp.asarray(st.qi), jnp.zeros(2)])[None])[0])
    put_in = E[0] - E_static
    err = np.max(np.abs(E - E[0])) / put_in
    first, last = _window(res, 0, 1), _window(res, 9, 10.01)
    drift = abs(E[last].mean() - E[first].mean()) / put_in
    print(f"\n  energy: {put_in * 1e3:.3f} mJ of vibration, max error {err:.1e}, drift {drift:.1e}")
    slide = float(sc.pulley("alternator").radius) * math.radians(sc.initial.rotation_deg[0][1])
    springs = _tangent_EA(sc, st.stretch) / (st.span_lengths_m / st.stretch)
    assert abs(put_in / (0.5 * np.sum(springs) * slide**2) - 1) < 0.01  # cubic term: 0.3 %
    assert err < 1e-7
    assert drift < 1e-9


def test_a_run_does_not_depend_on_where_it_is_cut_into_chunks(release):
    """simulate integrates in chunks (for its progress bar) and carries the solver's state from
    one chunk to the next: generalized-alpha's acceleration and its kept Newton matrix, the
    step-size controller's state.  The undamped release's first 0.5 s cut into five chunks
    equals the fixture's one-chunk start to round-off: 1e-12 of each channel's range.
    Restarting every chunk from y' = f(t, y), as simulate did before, moved the midpoint
    rule's acceleration at each cut: 9.3e-4 of the span forces' range here."""
    res = release["undamped"]
    cut = transient.simulate(release["undamped_scene"], 0.5, chunk_s=0.1)
    n = cut.t.size
    assert np.array_equal(cut.t, res.t[:n]) and n > 400
    for ch in ("span_forces_N", "pulley_speeds_rpm", "hub_forces_N"):
        a, b = cut.channels[ch], res.channels[ch][:n]
        err = np.max(np.abs(a - b)) / np.ptp(b)
        print(f"\n  {ch}: five chunks vs one, max difference {err:.1e} of the range")
        assert err < 1e-12, ch


def test_the_chunk_function_compiles_once(caplog):
    """The states handed from chunk to chunk have the types of those the run starts with (arrays,
    not the Python bool of diffrax's PID state), so an adaptive run compiles its chunk function
    once, not again at its second chunk (which doubled the first call's compile time)."""
    text = substitute(scene_text("sim_two_pulley_release.toml"), ('solver = "generalized_alpha" ', 'solver = "dopri8" '),
                      ("rho_inf = 1.0", "# (generalized-alpha's)"))
    with jax.log_compiles(True), caplog.at_level(logging.WARNING, logger="jax"):
        res = transient.simulate(loads_scene(text), 0.3, chunk_s=0.1)
    assert res.meta["solver"] == "dopri8"
    compiles = [r.getMessage() for r in caplog.records
                if r.getMessage().startswith("Finished XLA compilation of jit(_integrate_chunk)")]
    print(f"\n  {len(compiles)} compilation(s) of the chunk function for 3 chunks")
    assert len(compiles) == 1, compiles


def test_rotational_default_solver_release(release):
    """Without ``[simulation] solver`` the rotational model runs on its default, Dopri8 at
    rtol 1e-6 (transient.default_solver, chosen by benchmarks/bench_transient.py): the same
    undamped 10 s release.

    * the torsional frequency is the modal one itself, with no step-size error to correct:
      1e-4 (the generalized-alpha run above shows (omega dt)^2 / 12 = 1.3e-3 before its
      midpoint correction, so this could not pass by accident);
    * the energy: an explicit method does not conserve it, it drifts by the error accepted per
      step; at rtol 1e-6 it stays within 1e-3 of the vibration energy put in over 10 s (1000
      periods; measured 4.3e-4, drift 3.8e-4), against 3.5e-9 for the midpoint rule above:
      why the thesis' undamped runs name generalized_alpha in their scenes.
    """
    text = substitute(scene_text("sim_two_pulley_release.toml"), ("CA = 3.33 ", "CA = 0.0 "),
                      ('solver = "generalized_alpha" ', "# solver "),
                      ("rho_inf = 1.0", "# (generalized-alpha's rho_inf)"))
    sc = loads_scene(text)
    assert sc.simulation.solver is None and transient.default_solver(sc) == "dopri8"
    res = _simulate(sc, 10.0, "release, undamped, default solver")
    assert res.meta["solver"] == "dopri8"
    f_modal = release["modes"].frequencies_hz[1]
    f_sim = _dominant(res.t, _col(res, "pulley_speeds_rpm", "alternator"))
    st = release["statics"]
    energy = _energy_fn(sc, st.inst)
    E = np.asarray(energy(jnp.asarray(res.y)))
    E_static = float(energy(jnp.concatenate([jnp.asarray(st.qi), jnp.zeros(2)])[None])[0])
    put_in = E[0] - E_static
    err = np.max(np.abs(E - E[0])) / put_in
    drift = abs(E[_window(res, 9, 10.01)].mean() - E[_window(res, 0, 1)].mean()) / put_in
    print(f"\n  default solver: {res.meta['steps']} steps; torsional mode {f_sim:.4f} Hz (modal {f_modal:.4f}); "
          f"energy error {err:.1e}, drift {drift:.1e}")
    assert abs(f_sim / f_modal - 1) < 1e-4
    assert err < 1e-3 and drift < 1e-3


def test_release_damped_settles_on_the_static_reactions(ref, release):
    """With belt damping both spans return to the installation tension and the bearing
    reactions to the static ones (thesis Figs. 7.5-7.7: the last row of Table 7.1).

    * decay: the spans' Kelvin-Voigt damping is proportional to their stiffness, so the mode
      decays with damping ratio zeta = pi f CA / EA_t: within 2 % over 0.1-0.9 s (the
      envelope is read from 0.1 s windows: 10 periods, measured 0.2 %);
    * at 10 s the spans and bearings equal the statics to 1e-6 N (the transient has decayed
      by exp(-50));
    * the alternator bearing reaction is the thesis' Table 7.1 row at 601 N within 1 %
      (0.17 % of it is the 1 N tension difference, the rest the model difference that the
      statics tests allow 2 % for).
    """
    res, sc, st = release["damped"], release["damped_scene"], release["statics"]
    upper = _col(res, "span_forces_N", "alternator-crank")
    T0 = float(sc.belt.static_tension)
    f = release["modes"].frequencies_hz[1]
    zeta = math.pi * f * float(sc.belt.CA) / _tangent_EA(sc, st.stretch)
    env = [np.max(np.abs(upper[_window(res, a, a + 0.1)] - T0)) for a in (0.1, 0.8)]
    zeta_sim = math.log(env[0] / env[1]) / (0.7 * 2 * math.pi * f)
    print(f"\n  damping ratio: transient {zeta_sim:.5f}, Kelvin-Voigt {zeta:.5f}")
    assert abs(zeta_sim / zeta - 1) < 0.02
    end = res.t >= 9.9
    np.testing.assert_allclose(res.channels["span_forces_N"][end], T0, atol=1e-6)
    for name in ("crank", "alternator"):  # at rest: the force each pulley puts on its bearing
        np.testing.assert_allclose(_col(res, "hub_forces_N", name)[end],
                                   np.broadcast_to(st.hub_forces_N[name], (end.sum(), 2)), atol=1e-6)
    T, Fx, Fy = ref["two_pulley_bench"]["static_reactions_alternator_bearing"]["theory"][-1]
    F = _col(res, "hub_forces_N", "alternator")[-1]
    assert abs(T / T0 - 1) < 0.002
    assert abs(F[0] / Fx - 1) < 0.01 and abs(F[1] / Fy - 1) < 0.01, (F, Fx, Fy)


# =========================================================================== 7.1.1.3: fluctuation


@pytest.fixture(scope="module")
def fluct():
    """Sim 2 (thesis 7.1.1.3): crank driven at 600 rpm.  'forced': the scene (1 deg at 20 Hz,
    both pulleys unbalanced); 'free': neither, no damping, released from a 2 deg alternator
    rotation (same compiled structure: the effects stay listed with zero parameters)."""
    text = scene_text("sim_two_pulley_fluctuation.toml")
    forced = load_scene(SCENES / "sim_two_pulley_fluctuation.toml")
    free = loads_scene(substitute(
        text, ("fluctuation_amplitude_deg = 1.0", "fluctuation_amplitude_deg = 0.0"),
        ("cm_offset = [0.0005, 0.0]", "cm_offset = [0.0, 0.0]"), ("cm_offset = [0.001, 0.0]", "cm_offset = [0.0, 0.0]"),
        ("CA = 3.33 ", "CA = 0.0 "),
    ) + "\n[initial]\nrotation_deg = { alternator = 2.0 }\n")
    out = dict(forced_scene=forced, free_scene=free)
    out["forced"] = _simulate(forced, 3.0, "600 rpm, fluctuation and unbalance")
    out["free"] = _simulate(free, 3.0, "600 rpm, released alternator")
    out["modes"] = drive_modal.analyse_modes(free)
    return out


def test_fluctuation_free_vibration_is_the_crank_prescribed_mode(ref, fluct):
    """Without fluctuation and unbalance the bearing forces hold only the natural frequency
    excited by the initial condition (thesis Fig. 7.8): the alternator against the prescribed
    crank, thesis 81.8 Hz.  Transient vs modal analysis (midpoint-corrected): 1e-4 (0.03 bin
    of the 3 s record); vs the thesis 2.5 % (ours is 1.9 % higher, module docstring).  No line
    at the speed (10 Hz) or its harmonics: a steadily turning balanced drive is stationary."""
    thesis = ref["two_pulley_bench"]["rotational_model_checks"]["crank_prescribed_torsional_frequency_hz"]
    res, modes = fluct["free"], fluct["modes"]
    assert modes.labels == ["1st rotational (alternator)"]
    f_modal = modes.frequencies_hz[0]
    diff = _col(res, "span_forces_N", "alternator-crank") - _col(res, "span_forces_N", "crank-alternator")
    f_sim = _dominant(res.t, diff)
    print(f"\n  crank prescribed: transient {f_sim:.4f} Hz, modal {f_modal:.4f} Hz "
          f"(midpoint {_midpoint(f_modal, res.meta['dt_s']):.4f}), thesis {thesis} Hz")
    assert abs(f_sim / _midpoint(f_modal, res.meta["dt_s"]) - 1) < 1e-4
    assert abs(f_modal / thesis - 1) < 0.025
    hub = _col(res, "hub_forces_N", "crank")[:, 0]
    line = _tone(res.t, hub, f_sim)
    assert line > 1.0
    for f in (10.0, 20.0, 30.0, 40.0):
        assert _tone(res.t, hub, f) < 1e-6 * line, f


def test_fluctuation_and_unbalance_lines(fluct):
    """600 rpm with the 2x fluctuation and unbalance (thesis Figs. 7.9-7.10), after the start-up
    transient (1-3 s; it decays as exp(-t / 0.25 s)).  Which lines our model puts where, and why:

    * crank bearing (thesis F2): its unbalance turns at 10 Hz with the fluctuation in its
      angle, so the centre of mass, e exp(i theta), theta = w t + A sin(W t), carries lines
      at 10 + 20 k Hz (10, 30, 50, -10, ... Hz: odd multiples of 10 Hz, never 40 Hz).  Each
      equals that of the analytic -m d^2/dt^2 (e exp(i theta)) within 1 % (measured: to
      5 digits; the belt wrapped on the pulley turns on the axis and adds nothing);
    * 20 Hz: the prescribed crank swings the alternator; the spans carry the alternator's
      inertia torque, +-J W^2 r A / (2 R_a (1 - (W / w_n)^2)) = 18.2 N (1-DOF forced
      oscillator, w_n from the modal analysis): 0.5 % (measured 0.16 %); on the crank bearing this antisymmetric
      pair gives |t_1 + t_2| = 0.19 of it (the spans are nearly parallel): 2 %;
    * alternator bearing (thesis F1): its own unbalance at r x 10 = 27.07 Hz (1 %), with
      +-20 Hz side lines (7.07, 47.07 Hz); no 10 Hz line (fixed centres: the crank's
      unbalance stays in the crank's bearing);
    * 40 Hz (the thesis' "first harmonic" of the fluctuation): the system is linear but for
      two quadratic terms, the Green-Lagrange law's (3/4) EA lam delta^2 per span with delta
      the 20 Hz strain (2.2 mN) and the centrifugal force of the fluctuating belt speed,
      rhoA R^2 dw^2 / (2 lam) (3.0 mN; the thesis' T_c = rhoA c^2, eq. 4.17, has it too).
      Both are the same in the two spans, so they reach the crank bearing as the in-phase
      pair times t_1 - t_2 (10 mN along x): a line 3e-3 of the bearing's 20 Hz line, seen on
      the log-scale spectrum (``beltjax simulate``'s spectra.png), at the size these two
      terms give it (5 %).  The thesis prints no amplitude for it.
    """
    res, sc = fluct["forced"], fluct["forced_scene"]
    st = fluct["modes"].statics
    k = _window(res, 1.0, 3.01)
    t = res.t[k]
    crank, alt = sc.pulley("crank"), sc.pulley("alternator")
    s = float(sc.route.senses[sc.route.order.index("crank")])
    w = float(crank.speed_rpm) * 2 * math.pi / 60
    A = math.radians(float(crank.fluctuation_amplitude_deg))
    W = 2 * math.pi * float(crank.fluctuation_frequency_hz)
    r = float(crank.radius / alt.radius)
    # --- crank bearing: the unbalance's lines against the analytic centre-of-mass acceleration
    th = s * (w * t + A * np.sin(W * t))
    thd = s * (w + A * W * np.cos(W * t))
    thdd = -s * A * W**2 * np.sin(W * t)
    e = complex(*np.asarray(crank.cm_offset))
    z_pred = -float(crank.mass) * e * (1j * thdd - thd**2) * np.exp(1j * th)
    F = _col(res, "hub_forces_N", "crank")[k]
    z = F[:, 0] + 1j * F[:, 1]
    f0 = w / (2 * math.pi)
    for f in (s * f0, s * 3 * f0, -s * f0):
        ours, pred = _rotating(t, z, f), _rotating(t, z_pred, f)
        print(f"\n  crank bearing, line at {f:+.0f} Hz: {ours:.4f} N (analytic unbalance {pred:.4f} N)", end="")
        assert abs(ours / pred - 1) < 0.01, (f, ours, pred)
    # --- 20 Hz: the alternator's inertia through the spans
    inst = st.inst
    ia = sc.route.order.index("alternator")
    m_arc = float(sc.belt.rhoA * inst.radii[ia] * inst.wrap[ia]) / st.stretch
    Ja = float(alt.inertia) + m_arc * float(alt.radius) ** 2 + float(alt.mass) * float(jnp.sum(alt.cm_offset**2))
    wn = 2 * math.pi * fluct["modes"].frequencies_hz[0]
    dT = Ja * W**2 * r * A / (2 * float(alt.radius) * (1 - (W / wn) ** 2))
    f20 = W / (2 * math.pi)
    spans = [_tone(t, res.channels["span_forces_N"][k, j], f20) for j in range(2)]
    print(f"\n  span forces at 20 Hz: {spans} N (1-DOF {dT:.3f} N)")
    for a in spans:
        assert abs(a / dT - 1) < 0.005
    tangents = np.asarray(inst.span_tangent)
    hub20 = math.hypot(_tone(t, F[:, 0], f20), _tone(t, F[:, 1], f20))
    assert abs(hub20 / (np.mean(spans) * np.linalg.norm(tangents[0] + tangents[1])) - 1) < 0.02
    # --- alternator bearing: its own unbalance, no crank line
    Fa = _col(res, "hub_forces_N", "alternator")[k]
    za = Fa[:, 0] + 1j * Fa[:, 1]
    fa = r * f0
    main = _rotating(t, za, s * fa)
    pred = float(alt.mass) * float(jnp.linalg.norm(alt.cm_offset)) * (2 * math.pi * fa) ** 2
    print(f"  alternator bearing: {main:.3f} N at {fa:.2f} Hz (m e w^2 {pred:.3f} N); side lines "
          f"{_rotating(t, za, s * (fa + f20)):.3f}, {_rotating(t, za, s * (fa - f20)):.3f} N")
    assert abs(main / pred - 1) < 0.01
    assert _rotating(t, za, s * (fa + f20)) > 0.02 * main  # phase-modulation side line (7 %)
    assert max(_rotating(t, za, f0), _rotating(t, za, -f0)) < 1e-3 * main
    # --- 40 Hz: the Green-Lagrange quadratic term and the centrifugal term of the fluctuating
    # belt speed, rhoA c^2 lam with c = R (w + dw cos W t) / lam: rhoA R^2 dw^2 / (2 lam)
    EA, lam = float(sc.belt.EA), st.stretch
    crank = sc.pulley("crank")
    dw = math.radians(float(crank.fluctuation_amplitude_deg)) * 2 * math.pi * f20
    cf40 = float(sc.belt.rhoA) * (float(crank.radius) * dw) ** 2 / (2 * lam)
    for j, a20 in enumerate(spans):
        a40 = _tone(t, res.channels["span_forces_N"][k, j], 2 * f20)
        gl40 = 0.75 * EA * lam * (a20 / _tangent_EA(sc, lam)) ** 2
        print(f"  span {res.columns['span_forces_N'][j]}: 40 Hz {a40 * 1e3:.3f} mN "
              f"(Green-Lagrange {gl40 * 1e3:.3f} mN + centrifugal {cf40 * 1e3:.3f} mN)")
        assert abs(a40 / (gl40 + cf40) - 1) < 0.05  # the two come in phase
        assert a40 < 1e-3 * a20
    # ... and on the crank bearing, the in-phase pair along t_1 - t_2
    a40 = np.mean([_tone(t, res.channels["span_forces_N"][k, j], 2 * f20) for j in range(2)])
    hub40 = np.abs(a40 * (tangents[0] - tangents[1]))  # the route's second span ends on the crank
    for ax in (0, 1):
        ours = _tone(t, F[:, ax], 2 * f20)
        print(f"  crank bearing, {'xy'[ax]} at 40 Hz: {ours * 1e3:.3f} mN (in-phase span pair {hub40[ax] * 1e3:.3f} mN)")
        assert abs(ours - hub40[ax]) < 0.05 * np.max(hub40), (ax, ours, hub40)
    assert np.max(hub40) > 1e-3 * hub20


# =========================================================================== 7.1.1.4: run-up


@pytest.fixture(scope="module")
def runup():
    """Sim 3 (thesis 7.1.1.4): 68 rad/s^2 to 680 rad/s at 10 s, then 0.5 s at that speed."""
    sc = load_scene(SCENES / "sim_two_pulley_runup.toml")
    return dict(scene=sc, res=_simulate(sc, 10.5, "run-up to 680 rad/s, fixed centres"),
                rest=statics.analyse_statics(sc, speed=0.0))


def test_runup_alternator_load(runup, fluct):
    """The alternator load (-20 N m mean, -5 N m at 2 Hz, 1-5 s; thesis Figs. 7.12-7.13):

    * the spans' force difference carries it, M / R_a (torque balance on the alternator):
      mean over 2-5 s (six load periods, after the step's ringing decayed by exp(-4)) 0.1 %;
      the 2 Hz part with the quasi-static amplification 1 / (1 - (2 Hz / f_n)^2): 0.5 % (f_n
      of the same bench with the crank prescribed, from the fluctuation fixture);
    * before and after the load the difference is the alternator's own acceleration,
      J_a' r alpha / R_a (J_a' with the wrapped belt): 1 %;
    * the crank's drive torque rises by M R_c / R_a while the load acts (0.1 %) and returns
      to its run-up value (J_c' + r^2 J_a') alpha (1 %) afterwards (0.01 N m): thesis
      "the crank's drive torque rises to meet the alternator's demand".
    """
    res, sc, st = runup["res"], runup["scene"], runup["rest"]
    load = sc.torques[0]
    crank, alt = sc.pulley("crank"), sc.pulley("alternator")
    Ra, r = float(alt.radius), float(crank.radius / alt.radius)
    alpha = float(crank.acceleration_rpm_per_s) * 2 * math.pi / 60
    inst = st.inst
    J = {}
    for i, name in enumerate(sc.route.order):
        p = sc.pulley(name)
        m_arc = float(sc.belt.rhoA * inst.radii[i] * inst.wrap[i]) / st.stretch  # wrapped belt (kg)
        J[name] = float(p.inertia) + m_arc * float(p.radius) ** 2
    diff = np.abs(_col(res, "span_forces_N", "alternator-crank") - _col(res, "span_forces_N", "crank-alternator"))
    torque = np.abs(res.channels["drive_torques_Nm"][:, 0])
    before, during, after = _window(res, 0.5, 1.0), _window(res, 2.0, 5.0), _window(res, 6.0, 10.0)
    accel = J["alternator"] * r * alpha / Ra
    print(f"\n  span force difference: {diff[before].mean():.3f} N before, {diff[during].mean():.2f} N loaded "
          f"(M / R_a = {abs(float(load.mean_Nm)) / Ra:.2f} N), {diff[after].mean():.3f} N after; "
          f"drive torque {torque[before].mean():.4f} / {torque[during].mean():.3f} / {torque[after].mean():.4f} N m")
    for k in (before, after):
        assert abs(diff[k].mean() / accel - 1) < 0.01
    assert abs((diff[during].mean() - accel) / (abs(float(load.mean_Nm)) / Ra) - 1) < 1e-3
    f_n = fluct["modes"].frequencies_hz[0]
    f1 = float(load.frequency_hz)
    alt2 = _tone(res.t[during], diff[during], f1)
    assert abs(alt2 / (abs(float(load.amplitude_Nm)) / Ra / (1 - (f1 / f_n) ** 2)) - 1) < 0.005
    base = (J["crank"] + r**2 * J["alternator"]) * alpha
    assert abs(torque[before].mean() / base - 1) < 0.01
    assert abs(torque[after].mean() - torque[before].mean()) < 0.01
    assert abs((torque[during].mean() - torque[before].mean()) / (abs(float(load.mean_Nm)) * r) - 1) < 1e-3


def test_runup_centrifugal_force_unloads_fixed_centres(runup):
    """Fixed centres: the belt's elastic tension stays at the installation tension, and the
    span force on the pulleys falls by the centrifugal term rhoA c^2 lam = rhoA v^2 / lam
    (thesis eq. 4.17; Figs. 7.13-7.15: the bearing reactions fall with speed).

    * elastic tension, mean of both spans: T0 within 3e-3 N unloaded (before 1 s and from
      6 s on; the Green-Lagrange quadratic term of the acceleration's 8.4 N difference is
      2e-4 N, that of the load step's remaining ringing 1e-3 N at 6 s), within 2 N under the
      load from 2 s on (the quadratic term of the +-330 N swing: 1.5 N);
    * at 680 rad/s (69 m/s, 0.98 of the critical speed sqrt(T0 lam / rhoA)) the span force is
      T0 - rhoA v^2 / lam = 26.6 N, 4.4 % of T0 (thesis: "it can reach zero at high speeds"):
      0.05 N, mean of both spans (their difference rings after the acceleration stops);
    * quasi-static: the bearing forces follow analyse_statics(v(t)) within 1.5 N during the
      unloaded run-up (the alternator's acceleration needs 8.4 N of span force difference,
      0.19 of which reaches the bearing) and within 0.01 N at constant speed;
    * the crank bearing's force falls by rhoA v^2 / lam |t_1 - t_2| = 2 rhoA v^2 / lam cos(beta/2)
      (beta the angle between the spans): 0.1 %.
    """
    res, sc, st = runup["res"], runup["scene"], runup["rest"]
    T0, rhoA, lam = float(sc.belt.static_tension), float(sc.belt.rhoA), st.stretch
    v = res.channels["belt_speed_m_s"]
    tension = res.channels["span_tensions_N"].mean(axis=1)
    loaded = _window(res, 2.0, 5.0)  # after the load step's overshoot (+-1000 N) has decayed
    quiet = _window(res, 0.0, 1.0) | _window(res, 6.0, 10.0)  # unloaded, the load step's ringing decayed
    assert np.max(np.abs(tension[quiet] - T0)) < 3e-3
    assert np.max(np.abs(tension[loaded] - T0)) < 2.0
    top = _window(res, 10.1, 10.5)
    v_top = float(v[-1])
    crank = sc.pulley("crank")
    assert abs(v_top / (float(crank.target_speed_rpm) * 2 * math.pi / 60 * float(crank.radius)) - 1) < 1e-9
    force = res.channels["span_forces_N"][top].mean(axis=1)
    print(f"\n  680 rad/s (v = {v_top:.2f} m/s, critical {math.sqrt(T0 * lam / rhoA):.2f} m/s): span force "
          f"{force.mean():.3f} N (T0 - rhoA v^2 / lam = {T0 - rhoA * v_top**2 / lam:.3f} N)")
    assert np.max(np.abs(force - (T0 - rhoA * v_top**2 / lam))) < 0.05
    for tt in (7.0, 8.5, 10.0):
        i = int(np.argmin(np.abs(res.t - tt)))
        stv = statics.analyse_statics(sc, speed=float(v[i]))
        for name in ("crank", "alternator"):
            assert np.max(np.abs(_col(res, "hub_forces_N", name)[i] - stv.hub_forces_N[name])) < 1.5, (tt, name)
    stv = statics.analyse_statics(sc, speed=v_top)
    for name in ("crank", "alternator"):
        np.testing.assert_allclose(_col(res, "hub_forces_N", name)[top].mean(axis=0), stv.hub_forces_N[name], atol=0.01)
    t0_, t1_ = np.asarray(st.inst.span_tangent)
    drop = np.linalg.norm(st.hub_forces_N["crank"] - _col(res, "hub_forces_N", "crank")[top].mean(axis=0))
    estimate = rhoA * v_top**2 / lam * np.linalg.norm(t0_ - t1_)
    print(f"  crank bearing: {np.linalg.norm(st.hub_forces_N['crank']):.1f} N at rest, drop {drop:.1f} N "
          f"(2 rhoA v^2 / lam cos(beta/2) = {estimate:.1f} N)")
    assert abs(drop / estimate - 1) < 1e-3


def test_explicit_solver_out_of_steps_says_what_to_do():
    """An adaptive explicit solver that runs out of steps (here simulation.max_steps = 20 for a
    0.2 s run of the rotational bench, which needs about 100) fails with one line that names
    the solver, the time window, the cause and the remedy for a stiff model: generalized-alpha."""
    text = substitute(scene_text("two_pulley_T600.toml"), ('fidelity = "ancf"', 'fidelity = "rotational"'))
    sc = loads_scene(text + "\n[initial]\nrotation_deg = { alternator = 2.0 }\n[simulation]\nmax_steps = 20\n")
    with pytest.raises(transient.TransientError) as err:
        transient.simulate(sc, 0.2)
    msg = str(err.value)
    print(f"\n  {msg}")
    assert "\n" not in msg and msg.startswith("solver dopri8 failed between t = 0 s")
    assert "max_steps" in msg and 'simulation.solver = "generalized_alpha"' in msg


def test_free_crank_turned_by_a_torque_carries_its_centrifugal_force():
    """Rotational model, crank free (not driven) and accelerated from rest by a constant moment
    in the belt's direction of travel, both pulleys free, fixed centres, no damping, transport on.

    * the drive turns as one inertia: the crank's acceleration is M / J_eff with J_eff = J_c +
      J_a (R_c / R_a)^2 and the belt wrapped on each pulley (fit of the speed over 2 s: 1e-5;
      the torsional oscillation the moment starts adds a ripple);
    * the centrifugal force follows the crank's actual speed (c = R theta', as in the thesis;
      the nominal travel of a free crank is its speed_rpm, here 0): over the last 0.5 s the span
      force is the elastic tension minus rhoA c^2 lam_s, c = R_c theta'_c / lam, with each span's
      stretch lam_s, to 1e-6 of the installation tension, and the fall (46 N) is there (> 40 N).
    """
    M = -5.0  # N m, clockwise: the route's direction of travel ("cw")
    text = substitute(scene_text("two_pulley_T600.toml"), ('fidelity = "ancf"', 'fidelity = "rotational"'))
    text += f'\n[[torque]]\npulley = "crank"\nmean_Nm = {M}\nt_start_s = 0.0\n'
    sc = loads_scene(text)
    assert sc.model.has("transport") and not sc.pulley("crank").driven
    res = _simulate(sc, 2.0, "free crank, -5 N m from rest")
    st = statics.analyse_statics(sc)
    inst, lam, rhoA = st.inst, st.stretch, float(sc.belt.rhoA)
    (Jc, Rc), (Ja, Ra) = [(float(sc.pulley(n).inertia), float(sc.pulley(n).radius)) for n in ("crank", "alternator")]
    m_arc = rhoA * np.asarray(inst.radii) * np.asarray(inst.wrap) / lam
    J_eff = Jc + m_arc[0] * Rc**2 + (Ja + m_arc[1] * Ra**2) * (Rc / Ra) ** 2
    w = _col(res, "pulley_speeds_rpm", "crank") * 2 * math.pi / 60
    alpha = np.polyfit(res.t, w, 1)[0]
    late = res.t > 1.5
    v = np.abs(w[late]) * Rc
    force, tension = res.channels["span_forces_N"][late], res.channels["span_tensions_N"][late]
    # each span's stretch from its Green-Lagrange tension EA (l^2 - 1) l / 2: the momentum flux
    # rhoA c^2 l_s of belt moving at c = v / lam (m/s of unstretched belt)
    l_s = span.stretch_for_tension(tension, float(sc.belt.EA))
    fall = rhoA * (v[:, None] / lam) ** 2 * l_s
    print(f"\n  free crank: acceleration {alpha:.3f} rad/s^2 (M / J_eff {M / J_eff:.3f}); at {v.mean():.1f} m/s "
          f"the span force is {np.mean(tension - force):.2f} N below the tension (rhoA v^2 / lam {fall.mean():.2f} N)")
    assert abs(alpha / (M / J_eff) - 1) < 1e-5
    assert np.max(np.abs((tension - force) - fall)) < 1e-6 * float(sc.belt.static_tension)
    assert fall.mean() > 40.0
    np.testing.assert_allclose(res.channels["belt_speed_m_s"][late], v, rtol=1e-9)


def _free_crank_hybrid(moment_Nm, rpm=0.0, rotation_deg=None):
    """The two-pulley bench at T = 600 N, hybrid model with 3 elements per span, both pulleys
    free, transport on, undamped, midpoint rule (rho_inf = 1) at dt = 1e-4 s, a moment on the
    crank from t = 0 (N m; the same structure for every call, so one compilation serves all);
    optionally an initial belt speed (rpm) and an initial alternator rotation (deg)."""
    text = substitute(scene_text("two_pulley_T600.toml"),
                      ("elements_per_span = 16", "elements_per_span = 3"),
                      ("speed_rpm = 0.0            # static bench", f"speed_rpm = {rpm}"))
    assert 'effects = ["transport"]' in text and "driven = true" not in text
    text += f'\n[[torque]]\npulley = "crank"\nmean_Nm = {moment_Nm}\nt_start_s = 0.0\n'
    if rotation_deg is not None:
        text += f"\n[initial]\nrotation_deg = {{ alternator = {rotation_deg} }}\n"
    return loads_scene(text + '\n[simulation]\nsolver = "generalized_alpha"\ndt_s = 1e-4\nrho_inf = 1.0\n')


def test_hybrid_free_crank_turned_by_a_torque_carries_the_belt_with_it():
    """Hybrid model, crank free and accelerated from rest by -20 N m (clockwise, the route's
    direction of travel): in 0.5 s it turns 50 rad, to 2000 rpm (21 m/s).  The belt's travel
    follows the crank (drive.travel_follows_drive): its transport speed is the crank's rim speed
    and the spans' belt, moving with it, is inertia of the drive; before, the travel was the
    crank's speed_rpm (0) and the run stopped once the crank had turned half an element away.

    * acceleration (fit of the crank speed over the run) = M / J_eff to 1e-3, with J_eff =
      J_c + J_a (R_c / R_a)^2, the wrapped belt on each pulley and the spans' belt rhoA L0 R_c^2
      (L0: their unstretched length; 3.6 % of J_eff, so leaving it out fails);
    * the alternator turns at R_c / R_a times the crank's speed (no slip; 1e-3 on the last 0.1 s);
    * the belt speed output is the crank's rim speed, and the span force falls below the
      tension by the momentum flux rhoA c^2 lam of belt moving at c = v / lam (1e-3).
    """
    M = -20.0
    sc = _free_crank_hybrid(M)
    res = _simulate(sc, 0.5, "hybrid free crank, -20 N m from rest")
    st = statics.analyse_statics(sc)
    inst, lam, rhoA = st.inst, st.stretch, float(sc.belt.rhoA)
    (Jc, Rc), (Ja, Ra) = [(float(sc.pulley(n).inertia), float(sc.pulley(n).radius)) for n in ("crank", "alternator")]
    m_arc = rhoA * np.asarray(inst.radii) * np.asarray(inst.wrap) / lam
    L0 = float(np.sum(np.asarray(inst.span_length))) / lam
    J_rigid = Jc + m_arc[0] * Rc**2 + (Ja + m_arc[1] * Ra**2) * (Rc / Ra) ** 2
    J_eff = J_rigid + rhoA * L0 * Rc**2
    w = _col(res, "pulley_speeds_rpm", "crank") * 2 * math.pi / 60
    wa = _col(res, "pulley_speeds_rpm", "alternator") * 2 * math.pi / 60
    alpha = np.polyfit(res.t, w, 1)[0]
    late = res.t > 0.4
    ratio = np.mean(wa[late]) / np.mean(w[late])
    v = np.abs(w[late]) * Rc
    force, tension = res.channels["span_forces_N"][late], res.channels["span_tensions_N"][late]
    print(f"\n  hybrid free crank: acceleration {alpha:.3f} rad/s^2, M / J_eff {M / J_eff:.3f} "
          f"(without the spans' belt {M / J_rigid:.3f}); speed ratio {ratio:.5f} (R_c / R_a {Rc / Ra:.5f}); "
          f"crank turned {np.degrees(np.trapezoid(w, res.t)):.0f} deg; {v.mean():.1f} m/s at the end")
    assert abs(alpha / (M / J_eff) - 1) < 1e-3
    assert abs(ratio / (Rc / Ra) - 1) < 1e-3
    np.testing.assert_allclose(res.channels["belt_speed_m_s"][late], v, rtol=1e-9)
    l_s = span.stretch_for_tension(tension, float(sc.belt.EA))
    fall = rhoA * (v[:, None] / lam) ** 2 * l_s
    assert fall.mean() > 40.0
    assert np.max(np.abs((tension - force) / fall - 1)) < 1e-3


def test_hybrid_free_drive_spinning_keeps_its_energy():
    """Hybrid model, both pulleys free, spinning at 3000 rpm (belt 32 m/s) with no torque (0 N m) and no
    damping, the alternator released from 2 deg: a closed conservative system, whose energy
    (pulleys, the moving belt's 1/2 int rhoA |r_t + c r_x|^2 dx with c the crank's rim speed,
    strain) the midpoint rule keeps.  Over 0.2 s it stays within 1e-6 of the vibration's
    energy (the swing of the strain energy; measured 3e-9).  With the belt's travel prescribed
    (the crank's speed_rpm) while the crank is free, as before, the error was 2e-3: the prescribed
    speed pumped energy in and out."""
    sc = _free_crank_hybrid(0.0, rpm=3000.0, rotation_deg=2.0)
    res = _simulate(sc, 0.2, "hybrid free drive at 3000 rpm, alternator released")
    sc = drive.canonical(sc)
    inst = statics.install(sc)
    n, ni, ns = len(sc.route.order), drive.n_independent(sc), drive.n_span_coordinates(sc)
    idx = span.element_index(sc.model.elements_per_span)
    Le, mb = drive.element_length(sc, inst), drive.body_masses(sc, inst)

    def energy(t, y):
        qi, qd = y[:ni], y[ni:]
        q, v = jax.jvp(lambda x, s: drive.full_coordinates(x, sc, inst, t=s), (qi, t), (qd, jnp.ones_like(t)))
        E, Ed = q[:ns].reshape(n, -1), v[:ns].reshape(n, -1)
        c = drive.transient_transport_speed(sc, inst, v, t)[0]
        T = sum(span.span_kinetic_energy(E[s], Ed[s], c, sc.belt.rhoA, Le[s], idx) for s in range(n))
        U = sum(span.span_strain_energy(E[s], drive.section(sc), Le[s], idx, sc.model.bending) for s in range(n))
        return T + 0.5 * jnp.sum(mb * v[ns:] ** 2) + U, U

    E, U = (np.asarray(a) for a in jax.jit(jax.vmap(energy))(jnp.asarray(res.t), jnp.asarray(res.y)))
    w = _col(res, "pulley_speeds_rpm", "crank")
    swing = U.max() - U.min()
    print(f"\n  energy {E[0]:.3f} J, drift {np.max(np.abs(E - E[0])):.2e} J, vibration {swing:.3f} J; "
          f"crank {w.min():.1f} to {w.max():.1f} rpm")
    assert swing > 0.1 and w.max() - w.min() > 10.0  # it vibrates, and the crank with it
    assert np.max(np.abs(E - E[0])) < 1e-6 * swing


# =========================================================================== 7.2.1.2: tensioner installation


def _unstretched_state(scene):
    """(arm angle rad, idler rotation rad, alternator rotation rad) at which every span of the
    model's belt is at zero tension, by Newton on the kinematic map about the static state."""
    st = statics.analyse_statics(scene)
    idx = transient._rigid_index(scene)

    @eqx.filter_jit
    def solve(scene, inst):
        def tensions(x):
            qi = jnp.zeros(3).at[idx["arm"]].set(x[0] - inst.arm_angle)
            qi = qi.at[idx["tensioner"]].set(x[1]).at[idx["alternator"]].set(x[2])
            return drive.span_tensions(drive.full_coordinates(qi, scene, inst), scene, inst)

        x = jnp.stack([inst.arm_angle, 0.0, 0.0])
        for _ in range(8):
            x = x - jnp.linalg.solve(jax.jacfwd(tensions)(x), tensions(x))
        return x, tensions(x)

    x, T = solve(drive.canonical(scene), st.inst)
    assert float(jnp.max(jnp.abs(T))) < 1e-6
    return np.asarray(x), st


@pytest.fixture(scope="module")
def installation():
    """Tensioner Sim 1 (thesis 7.2.1.2): from the unstretched belt, arm released, 3 s."""
    sc = load_scene(SCENES / "sim_tensioner_installation.toml")
    x, st = _unstretched_state(sc)
    res = _simulate(sc, 3.0, "tensioner installation")
    return dict(scene=sc, res=res, statics=st, unstretched=x)


def test_a_start_no_belt_stretches_to_is_refused(installation):
    """An [initial] rotation of turns (3000 deg of the alternator: metres of belt pulled through
    its spans) is a one-line error naming the [initial] table before any step (it ran into a
    solver failure at t = 0 with a matplotlib warning on stderr); the shipped start (a slack
    belt, the arm released) passes, as the fixture shows."""
    from beltjax.errors import BeltjaxError

    text = (SCENES / "sim_tensioner_installation.toml").read_text()
    bad = substitute(text, ("alternator = -4.181391", "alternator = -3000.0"))
    with pytest.raises(BeltjaxError, match="stretches span .* beyond the 2 %") as e:
        transient.simulate(loads_scene(bad), 0.01)
    assert e.value.key == "initial"


def test_tensioner_installation_starts_from_the_unstretched_belt(ref, installation):
    """The scene's [initial] is the state where the belt carries no force (section 7.2.1.2:
    "no effort at the bearings"): every span at zero tension, and the crank's and the
    alternator's bearings unloaded at t = 0 (1e-3 N).

    The belt length is the exact path at the thesis' installation angle, 44.3 deg, yet the
    spans are unstretched 3.3 deg further out: the model keeps the belt wrapped on the
    pulleys at its installed strain (lam - 1), so the spans must make up (1 - 1/lam) times
    the wrapped length, 2.3 mm.  That angle follows from the exact belt path alone,
    path(theta) = L0 + (1 - 1/lam) x wrapped length, to 1e-6 deg: the map's tangent points
    are exact and the belt it moves between arcs and spans keeps the length (with tangent
    points carried rigidly by the idler centre, first order, it was 0.005 deg off).
    """
    sc, res, st, x = installation["scene"], installation["res"], installation["statics"], installation["unstretched"]
    ini = sc.initial
    rot = dict(ini.rotation_deg)
    np.testing.assert_allclose([ini.arm_angle_deg, rot["tensioner"], rot["alternator"]], np.degrees(x), atol=1e-5)
    np.testing.assert_allclose(res.channels["span_tensions_N"][0], 0.0, atol=1e-3)
    for name in ("crank", "alternator"):
        assert np.max(np.abs(_col(res, "hub_forces_N", name)[0])) < 1e-3
    assert abs(res.channels["arm_angle_deg"][0] - ini.arm_angle_deg) < 1e-9
    inst = st.inst
    target = float(inst.belt_length) + float(jnp.sum(inst.radii * inst.wrap)) * (1 - 1 / st.stretch)
    th = jnp.radians(ref["tensioner_bench_stage2"]["installation"]["belt_fits_unstretched_at_arm_angle_deg"])
    assert abs(float(statics._arm_terms(th, sc)[0]) - float(inst.belt_length)) < 1e-8  # length = path(44.3 deg)
    path = lambda a: statics._arm_terms(a, sc)[0]  # noqa: E731
    step = jax.jit(lambda a: a - (path(a) - target) / jax.grad(path)(a))
    for _ in range(6):
        th = step(th)
    print(f"\n  unstretched belt: arm at {np.degrees(x[0]):.4f} deg (exact path: {float(jnp.degrees(th)):.4f} deg, "
          f"{float(jnp.degrees(th)) - np.degrees(x[0]):+.1e}), idler {np.degrees(x[1]):+.3f} deg, "
          f"alternator {np.degrees(x[2]):+.3f} deg")
    assert abs(float(jnp.degrees(th)) - np.degrees(x[0])) < 1e-6


def test_tensioner_installation_settles_on_the_static_equilibrium(installation):
    """Released, the arm swings out and the drive settles (thesis Figs. 7.30-7.39) on the
    static equilibrium of tensioner_bench_stage2.toml's drive (56.44 deg, 469.5 N: the
    printed stage-2 spring cannot hold the thesis' 497 N, see that scene):

    * from 2.9 s on (the slowest mode, the alternator's at 90 Hz with damping ratio 0.01, has
      decayed by exp(-17)): arm angle 1e-5 deg, span tensions, bearing forces (tensioner
      pivot included) and spring moment as the statics to 1e-4 N (N m), the held crank's
      reaction moment zero to 1e-4 N m;
    * all spans converge to one tension, the one the spring holds at the settled angle,
      k (theta_0 - theta) / (moment arm per unit tension of the exact geometry): 1e-6;
    * the idler turns clockwise and the alternator counter-clockwise on the way (thesis
      Figs. 7.31-7.32);
    * damped, with the crank held (no power in): the mechanical energy never rises (1e-9 of
      the energy released allowed for the midpoint rule's O(dt^2) error on the Green-Lagrange
      energy).
    """
    sc, res, st = installation["scene"], installation["res"], installation["statics"]
    end = res.t >= 2.9
    print(f"\n  settled: arm {res.channels['arm_angle_deg'][-1]:.5f} deg (statics {st.tensioner_angle_deg:.5f}), "
          f"tensions {res.channels['span_tensions_N'][-1]} N (statics {st.span_tensions_N})")
    assert np.max(np.abs(res.channels["arm_angle_deg"][end] - st.tensioner_angle_deg)) < 1e-5
    assert np.max(np.abs(res.channels["span_tensions_N"][end] - st.span_tensions_N)) < 1e-4
    assert np.max(np.abs(res.channels["spring_moment_Nm"][end] - st.spring_moment_Nm)) < 1e-4
    assert np.max(np.abs(res.channels["drive_torques_Nm"][end])) < 1e-4
    for name in ("crank", "tensioner", "alternator"):
        assert np.max(np.abs(_col(res, "hub_forces_N", name)[end] - st.hub_forces_N[name])) < 1e-4, name
    assert np.max(np.abs(_col(res, "hub_forces_N", "tensioner pivot")[end] - st.tensioner_pivot_force_N)) < 1e-4
    theta = math.radians(st.tensioner_angle_deg)
    _, arm, _ = statics._arm_terms(jnp.asarray(theta), sc)
    t = sc.tensioner
    T_spring = float(t.spring_stiffness) * (math.radians(float(t.spring_preload_deg)) - theta) / -float(arm)
    assert np.max(np.abs(st.span_tensions_N / T_spring - 1)) < 1e-6
    turned = res.channels["pulley_rotations_deg"][-1] - res.channels["pulley_rotations_deg"][0]
    order = list(sc.route.order)
    assert turned[order.index("tensioner")] < 0 < turned[order.index("alternator")]
    E = np.asarray(_energy_fn(sc, st.inst)(jnp.asarray(res.y)))
    released = E[0] - E[-1]
    rise = np.max(np.diff(E))
    print(f"  energy released {released:.4f} J, largest rise between outputs {rise:.1e} J")
    assert released > 0.5
    assert rise < 1e-9 * released


# =========================================================================== 7.2.1.3: tensioner, fluctuation and load


@pytest.fixture(scope="module")
def tensioner_pulses():
    """Tensioner Sim 2 (thesis 7.2.1.3): crank at 600 rpm with 1 deg at 20 Hz, 30 N m on the
    alternator over 1-3 s and 5-7 s."""
    sc = load_scene(SCENES / "sim_tensioner_fluctuation_load.toml")
    return dict(scene=sc, res=_simulate(sc, 8.0, "tensioner, fluctuation and alternator pulses"))


def test_tensioner_fluctuation_and_load_pulses(tensioner_pulses):
    """Thesis 7.2.1.3 (Figs. 7.41-7.54), its statements one by one.  Windows of whole 20 Hz
    periods: before the first pulse (0.5-1 s), late in each pulse (2-3 s, 6-7 s; the ringing
    of the arm's 26 Hz mode after the step has died out by then), after it (4-5 s).

    * the tensioner vibrates at the fluctuation's frequency (20 Hz dominant) and each pulse
      opens the arm (thesis: the angle grows, T1 stretches); it comes back to where it was
      (4-5 s vs 0.5-1 s: 1e-3 deg) and both pulses give the same state (1e-6 deg);
    * the crank's fluctuation (41.9 rpm peak to peak, 2x) reaches the other pulleys, more
      strongly at the idler and the alternator (thesis Figs. 7.44-7.46): their 20 Hz speed
      swing exceeds the crank's, and the rigid-belt ratio R_c / R_i x the crank's;
    * in the mean the alternator's moment goes into T1 alone: T1 - T3 = M / R_a and T2 = T3
      (1e-4; no bearing damping), and the crank's holding torque rises by M R_c / R_a (thesis
      Fig. 7.52: "the torque demand rises proportionally"), 1e-4;
    * the tensioner keeps T2 and T3 near their level (within 5 %; the spring's tension k
      (theta_0 - theta) / arm(theta) rises 3.5 % as the arm opens) while T1 takes 800 N, and
      T1's 20 Hz swing is larger than T2's and T3's (thesis Figs. 7.53-7.54), unloaded and
      loaded;
    * the 30 N m step (applied in zero time) slackens the spans for a few ms after each
      pulse edge (T2, T3 at its start, T1 at its end): reported in meta["slack_spans"]; the
      drive is taut everywhere else.
    """
    res, sc = tensioner_pulses["res"], tensioner_pulses["scene"]
    load = sc.torques[0]
    M = float(load.mean_Nm)
    crank, alt, ten = sc.pulley("crank"), sc.pulley("alternator"), sc.tensioner
    Ra, Rc, Ri = float(alt.radius), float(crank.radius), float(ten.pulley_radius)
    f = float(crank.fluctuation_frequency_hz)
    W = {name: _window(res, a, b) for name, a, b in
         (("before", 0.5, 1.0), ("pulse", 2.0, 3.0), ("after", 4.0, 5.0), ("pulse2", 6.0, 7.0))}
    arm = res.channels["arm_angle_deg"]
    mean = {k: arm[w].mean() for k, w in W.items()}
    print(f"\n  arm: {mean['before']:.3f} deg before, {mean['pulse']:.3f} deg loaded, {mean['after']:.3f} deg after")
    assert mean["pulse"] > mean["before"] + 2.0
    assert abs(mean["after"] - mean["before"]) < 1e-3 and abs(mean["pulse2"] - mean["pulse"]) < 1e-6
    for w in (W["before"], W["pulse"]):
        assert abs(_dominant(res.t[w], arm[w]) / f - 1) < 0.01
    speeds = {name: _col(res, "pulley_speeds_rpm", name) for name in ("crank", "tensioner", "alternator")}
    F = {name: _col(res, "span_forces_N", name) for name in res.columns["span_forces_N"]}
    T1, T2, T3 = F["alternator-crank"], F["crank-tensioner"], F["tensioner-alternator"]
    torque = _col(res, "drive_torques_Nm", "crank")
    for key in ("before", "pulse"):
        w = W[key]
        t = res.t[w]
        swing = {name: _tone(t, v[w], f) for name, v in speeds.items()}
        print(f"  {key}: 20 Hz speed swing {swing} rpm; mean T1 {T1[w].mean():.2f}, T2 {T2[w].mean():.2f}, "
              f"T3 {T3[w].mean():.2f} N; 20 Hz swing T1 {_tone(t, T1[w], f):.1f}, T2 {_tone(t, T2[w], f):.1f}, "
              f"T3 {_tone(t, T3[w], f):.1f} N; crank torque {torque[w].mean():.3f} N m")
        assert abs(swing["crank"] / (math.radians(float(crank.fluctuation_amplitude_deg)) * 2 * math.pi * f
                                    * 60 / (2 * math.pi)) - 1) < 1e-3
        assert swing["tensioner"] > Rc / Ri * swing["crank"] and swing["alternator"] > Rc / Ra * swing["crank"]
        assert _tone(t, T1[w], f) > max(_tone(t, T2[w], f), _tone(t, T3[w], f))
        assert abs(T2[w].mean() / T3[w].mean() - 1) < 1e-4
    p, b = W["pulse"], W["before"]
    assert abs((T1[p].mean() - T3[p].mean()) / (M / Ra) - 1) < 1e-4
    assert abs(T1[b].mean() - T3[b].mean()) < 1e-4 * M / Ra
    assert abs((torque[b].mean() - torque[p].mean()) / (M * Rc / Ra) - 1) < 1e-4
    for T in (T2, T3):
        assert abs(T[p].mean() / T[b].mean() - 1) < 0.05
    # slack only just after the pulse edges, and reported
    slack = {r["span"]: r for r in res.meta["slack_spans"]}
    print(f"  slack: {slack}")
    assert set(slack) == {"crank-tensioner", "tensioner-alternator", "alternator-crank"}
    taut = np.ones(res.t.size, bool)
    for edge in (1.0, 3.0, 5.0, 7.0):
        taut &= ~((res.t >= edge) & (res.t < edge + 0.1))
    assert np.all(res.channels["span_tensions_N"][taut] > 0)
    for name in ("crank-tensioner", "tensioner-alternator"):
        assert 1.0 <= slack[name]["t_first_s"] < 1.1
    assert 3.0 <= slack["alternator-crank"]["t_first_s"] < 3.1


# =========================================================================== 7.2.1.4: tensioner run-up


@pytest.fixture(scope="module")
def tensioner_runup():
    """Tensioner Sim 3 (thesis 7.2.1.4): 100 rad/s^2 to 600 rad/s (6 s), alternator load 1-5 s."""
    sc = load_scene(SCENES / "sim_tensioner_runup.toml")
    return dict(scene=sc, res=_simulate(sc, 6.5, "tensioner run-up"), rest=statics.analyse_statics(sc, speed=0.0))


def test_tensioner_runup_scene_sits_at_the_thesis_arm_angle(ref, tensioner_runup):
    """The run-up scene's belt length puts the static arm at the thesis' rotational-model angle
    (46.8 deg; 1e-3 deg: the length is printed to 1e-10 m), where the stage-2 spring holds
    455.6 N, 8 % below the thesis' printed 497 N (that spring cannot hold 497 N at any arm
    angle between 40 and 57 deg, tests/test_drive.py)."""
    st = tensioner_runup["rest"]
    static = ref["tensioner_bench_stage2"]["static"]
    assert abs(st.tensioner_angle_deg - static["arm_angle_deg_rotational_model"]) < 1e-3
    assert 0.90 < st.span_tensions_N.mean() / static["T_theory"] < 0.93


def test_tensioner_runup_load(tensioner_runup):
    """The alternator load (20 N m + 5 N m at 3 Hz, 1-5 s; thesis Figs. 7.55-7.64):

    * the upper span T1 (alternator-crank, not touching the tensioner) takes it: the mean
      difference to the idler's spans is M / R_a plus the alternator's acceleration torque
      J_a' r alpha / R_a (12.4 N): 1 %; its 3 Hz swing is M_a / R_a: 3 % (the arm's 21 Hz mode
      adds 2 %), at least 10x that of T2 and T3 (thesis Fig. 7.64: the tensioner keeps them);
    * T2 and T3 stay within 3 % of their unloaded (static) value at the same speed.
    """
    res, sc, st = tensioner_runup["res"], tensioner_runup["scene"], tensioner_runup["rest"]
    load = sc.torques[0]
    crank, alt = sc.pulley("crank"), sc.pulley("alternator")
    Ra, r = float(alt.radius), float(crank.radius / alt.radius)
    alpha = float(crank.acceleration_rpm_per_s) * 2 * math.pi / 60
    ia = sc.route.order.index("alternator")
    m_arc = float(sc.belt.rhoA * st.inst.radii[ia] * st.inst.wrap[ia]) / st.stretch
    accel = (float(alt.inertia) + m_arc * Ra**2) * r * alpha / Ra
    k = _window(res, 2.0, 5.0)
    t = res.t[k]
    T = {name: _col(res, "span_forces_N", name)[k] for name in res.columns["span_forces_N"]}
    T1, T2, T3 = T["alternator-crank"], T["crank-tensioner"], T["tensioner-alternator"]
    diff = T1 - (T2 + T3) / 2
    print(f"\n  loaded: T1 - T2,3 = {diff.mean():.2f} N "
          f"(M / R_a + J a / R_a = {float(load.mean_Nm) / Ra + accel:.2f} N); "
          f"3 Hz: T1 - T2,3 {_tone(t, diff, 3.0):.2f} N (M_a / R_a = {float(load.amplitude_Nm) / Ra:.2f} N), "
          f"T1 {_tone(t, T1, 3.0):.2f} N, T2 {_tone(t, T2, 3.0):.2f} N, T3 {_tone(t, T3, 3.0):.2f} N")
    assert abs(diff.mean() / (float(load.mean_Nm) / Ra + accel) - 1) < 0.01
    f3 = float(load.frequency_hz)
    assert abs(_tone(t, diff, f3) / (float(load.amplitude_Nm) / Ra) - 1) < 0.03
    assert _tone(t, T1, f3) > 10 * max(_tone(t, T2, f3), _tone(t, T3, f3))
    v = res.channels["belt_speed_m_s"]
    for tt in (3.0, 4.0):
        i = int(np.argmin(np.abs(res.t - tt)))
        stv = statics.analyse_statics(sc, speed=float(v[i]))
        for name in ("crank-tensioner", "tensioner-alternator"):
            j = res.columns["span_tensions_N"].index(name)
            assert abs(res.channels["span_tensions_N"][i, j] / stv.span_tensions_N[j] - 1) < 0.03, (tt, name)


def test_tensioner_runup_centrifugal_force_raises_the_tension(tensioner_runup, runup):
    """With the tensioner the centrifugal force raises the belt's elastic tension (thesis
    7.2.1.4, Figs. 7.56, 7.61, 7.63): the spring keeps the span force on the pulleys, T - rhoA
    c^2 lam, near its value at rest, so the elastic tension rises by about rhoA v^2 / lam, and
    the arm opens (the spring moment falls).  On fixed centres (7.1.1.4) the elastic tension
    stays and the span force falls instead.

    * at constant top speed (600 rad/s, 61 m/s) the state is the steady-motion statics: the
      ringing left by the end of the acceleration at 6 s (the arm's 21 Hz mode, damping ratio
      0.085, and the alternator's 91 Hz mode, 0.01) averages out over 6.1-6.5 s: arm within
      2e-3 deg (measured 2e-4), tensions within 0.05 N (measured 0.02);
    * elastic tension rise / (rhoA v^2 / lam): between 1.0 and 1.1 (measured 1.027: the
      spring's tension k (theta_0 - theta) / arm(theta) grows as the arm opens); span force
      within 5 % of its value at rest; fixed centres: rise below 1e-5 of rhoA v^2 / lam;
    * the arm angle grows with speed (statics at rest, half and full speed; the transient ends
      open by the same amount).
    """
    res, sc, st = tensioner_runup["res"], tensioner_runup["scene"], tensioner_runup["rest"]
    v_top = float(res.channels["belt_speed_m_s"][-1])
    top = _window(res, 6.1, 6.51)
    stv = statics.analyse_statics(sc, speed=v_top)
    arm = res.channels["arm_angle_deg"][top].mean()
    tensions = res.channels["span_tensions_N"][top].mean(axis=0)
    print(f"\n  600 rad/s: arm {arm:.4f} deg (statics {stv.tensioner_angle_deg:.4f}), tensions {tensions} N "
          f"(statics {stv.span_tensions_N})")
    assert abs(arm - stv.tensioner_angle_deg) < 2e-3
    assert np.max(np.abs(tensions - stv.span_tensions_N)) < 0.05
    rhoA = float(sc.belt.rhoA)
    centrifugal = rhoA * v_top**2 / st.stretch
    rise = tensions.mean() - st.span_tensions_N.mean()
    force = res.channels["span_forces_N"][top].mean()
    print(f"  elastic tension rise {rise:.1f} N = {rise / centrifugal:.3f} rhoA v^2 / lam; span force "
          f"{force:.1f} N (at rest {st.span_tensions_N.mean():.1f} N)")
    assert 1.0 < rise / centrifugal < 1.1
    assert abs(force / st.span_tensions_N.mean() - 1) < 0.05
    fixed = runup["res"]
    v_fixed = float(fixed.channels["belt_speed_m_s"][-1])
    T0_fixed = float(runup["scene"].belt.static_tension)
    rise_fixed = fixed.channels["span_tensions_N"][_window(fixed, 10.1, 10.5)].mean() - T0_fixed
    assert abs(rise_fixed) < 1e-5 * float(runup["scene"].belt.rhoA) * v_fixed**2
    angles = [statics.analyse_statics(sc, speed=s * v_top).tensioner_angle_deg for s in (0.0, 0.5, 1.0)]
    assert angles[0] < angles[1] < angles[2]
    assert abs(arm - angles[2]) < 2e-3 and angles[2] - angles[0] > 5.0


# =========================================================================== 7.1.2.4: hybrid model


HYBRID_T_END = 1.0  # s, every hybrid run (one compiled output function)


def _hybrid_scene(speed_rpm=0.0, amplitude=0.0, frequency=0.0, phase=0.0, t_start=0.0, t_end=100.0):
    """The 7.1.2.4 scene with transport listed (for the runs at speed) and the span load set."""
    speed_rpm, amplitude, frequency = float(speed_rpm), float(amplitude), float(frequency)
    phase, t_start, t_end = float(phase), float(t_start), float(t_end)
    text = substitute(
        scene_text("sim_two_pulley_span_resonance.toml"),
        ('effects = ["gravity"]', 'effects = ["transport", "gravity"]'),
        ("speed_rpm = 0.0 ", f"speed_rpm = {speed_rpm!r} "),
        ("amplitude_N = 0.02 ", f"amplitude_N = {amplitude!r} "),
        ("frequency_hz = 52.3 ", f"frequency_hz = {frequency!r}\nphase_deg = {phase!r}\n"
                                 f"t_start_s = {t_start!r}\nt_end_s = {t_end!r} "),
    )
    return loads_scene(text)


@pytest.fixture(scope="module")
def hybrid(ref):
    """Hybrid runs of 1 s: harmonic span loads at (and 20 % below) the 1st transverse and the
    1st rotational frequency (thesis 7.1.2.4); 5 ms pulses at rest (small and large) and at
    0.85 of the critical belt speed."""
    base = load_scene(SCENES / "sim_two_pulley_span_resonance.toml")
    case = next(c for c in ref["two_pulley_bench"]["modal"]["cases"] if c["T"] == 600)
    rest = _hybrid_scene()
    modes = drive_modal.analyse_modes(rest)
    f_t = next(f for f, lab in zip(modes.frequencies_hz, modes.labels) if lab.startswith("1st transverse"))
    f_r = next(f for f, lab in zip(modes.frequencies_hz, modes.labels) if lab.startswith("1st rotational"))
    F_t, F_r = float(base.span_loads[0].amplitude_N), 10 * float(base.span_loads[0].amplitude_N)  # thesis: 0.02, 0.2 N
    st = modes.statics
    T0, lam, rhoA = float(base.belt.static_tension), st.stretch, float(base.belt.rhoA)
    v_c = math.sqrt(T0 * lam / rhoA)  # span force T - rhoA v^2 / lam vanishes
    v = 0.85 * v_c
    rpm = v / float(base.pulley("crank").radius) * 60 / (2 * math.pi)
    pulse = dict(frequency=0.0, phase=90.0, t_start=0.05, t_end=0.055)  # a 5 ms constant force
    runs = dict(
        transverse=(F_t, f_t, 0.0), transverse_off=(F_t, 0.8 * f_t, 0.0),
        rotational=(F_r, f_r, 0.0), rotational_off=(F_r, 0.8 * f_r, 0.0),
    )
    out = dict(case=case, modes=modes, f_t=f_t, f_r=f_r, v=v, v_c=v_c, rest_scene=rest)
    for name, (F, f, rpm_) in runs.items():
        out[name] = _simulate(_hybrid_scene(rpm_, F, f), HYBRID_T_END, f"hybrid {name}: {F} N at {f:.3f} Hz")
    out["critical_scene"] = _hybrid_scene(rpm, 2.0, **pulse)
    out["critical"] = _simulate(out["critical_scene"], HYBRID_T_END, f"hybrid, 2 N pulse at {v:.1f} m/s")
    out["critical_modes"] = drive_modal.analyse_modes(out["critical_scene"], v)
    out["small_scene"] = _hybrid_scene(0.0, 0.4, **pulse)
    out["small"] = _simulate(out["small_scene"], HYBRID_T_END, "hybrid, 0.4 N pulse at rest")
    out["large_scene"] = _hybrid_scene(0.0, 40.0, **pulse)
    out["large"] = _simulate(out["large_scene"], HYBRID_T_END, "hybrid, 40 N pulse at rest")
    return out


def _node(res, name):
    x = _col(res, "node_displacements_m", name)
    return x - x[0]


def test_span_load_at_the_transverse_frequency_couples_through_the_pulleys(hybrid):
    """Thesis 7.1.2.4 (Fig. 7.27): 0.02 N at the 1st transverse frequency, normal to the lower
    span's middle, drives that span into resonance, and the upper span's middle too.

    * the frequency we force at is the modal analysis' (52.21 Hz; thesis 52.3 Hz, 0.5 %);
    * loaded span: amplitude grows linearly (undamped resonance): the 52 Hz amplitude over
      0.8-1.0 s is 2.25x that over 0.3-0.5 s (window centres 0.9 and 0.4 s), 1.9-2.6 allowed;
    * upper span: forced at its own frequency (equal tension and length) by a force that
      grows with the loaded span, it grows like t^2 (ratio 5.1 expected, 4-6.5 allowed), at
      the same frequency (0.5 %), and ends at least 20x above its response when the load is
      20 % off resonance;
    * the path: the sagging spans (belt weight) turn transverse motion into stretching, so the
      upper span's force carries a 52 Hz line that grows with the loaded span (linear
      coupling: ratio 1.9-2.6), beside the 104 Hz line of the loaded span's quadratic
      stretching (ratio (0.9 / 0.4)^2 = 5.1: 4-6.5).  Without the belt's weight the spans are
      straight, the 52 Hz line vanishes and the upper span stays at rest to 1e-15 m (checked
      when writing this test; not run, it needs a second compiled model).
    """
    f_t, case = hybrid["f_t"], hybrid["case"]
    thesis = next(m[1] for m in case["modes"] if m[3] == "1st transverse")
    assert abs(f_t / thesis - 1) < 0.005
    on, off = hybrid["transverse"], hybrid["transverse_off"]
    early, late = _window(on, 0.3, 0.5), _window(on, 0.8, 1.01)
    loaded, other = _node(on, "crank-alternator:3"), _node(on, "alternator-crank:3")
    grow_loaded = _tone(on.t[late], loaded[late], f_t) / _tone(on.t[early], loaded[early], f_t)
    grow_other = _tone(on.t[late], other[late], f_t) / _tone(on.t[early], other[early], f_t)
    ratio = np.max(np.abs(other[late])) / np.max(np.abs(_node(off, "alternator-crank:3")[late]))
    print(f"\n  transverse resonance at {f_t:.3f} Hz: loaded span {np.max(np.abs(loaded)) * 1e3:.3f} mm "
          f"(growth {grow_loaded:.2f}), other span {np.max(np.abs(other)) * 1e6:.3f} um (growth {grow_other:.2f}, "
          f"{ratio:.0f}x off resonance)")
    assert 1.9 < grow_loaded < 2.6
    assert 4.0 < grow_other < 6.5
    assert abs(_dominant(on.t[late], other[late]) / f_t - 1) < 0.005
    assert ratio > 20
    upper = _col(on, "span_forces_N", "alternator-crank")
    lin = _tone(on.t[late], upper[late], f_t) / _tone(on.t[early], upper[early], f_t)
    quad = _tone(on.t[late], upper[late], 2 * f_t) / _tone(on.t[early], upper[early], 2 * f_t)
    print(f"  upper span force: {_tone(on.t[late], upper[late], f_t) * 1e3:.2f} mN at f_t (growth {lin:.2f}), "
          f"{_tone(on.t[late], upper[late], 2 * f_t) * 1e3:.2f} mN at 2 f_t (growth {quad:.2f})")
    assert 1.9 < lin < 2.6
    assert 4.0 < quad < 6.5


def test_span_load_at_the_rotational_frequency_drives_the_pulleys(hybrid):
    """Thesis 7.1.2.4 (Fig. 7.28): 0.2 N at the 1st rotational frequency on the same node puts
    the pulleys in resonance (mode 4 of the thesis, 96.5 Hz; ours 96.81 Hz, 0.5 %): the spans'
    antisymmetric force, (T_upper - T_lower) / 2, which the pulleys' opposed rotation makes,
    grows linearly (ratio 1.9-2.6 as above), at f_r (0.5 %), and ends at least 5x above its
    response 20 % off resonance."""
    f_r, case = hybrid["f_r"], hybrid["case"]
    thesis = next(m[1] for m in case["modes"] if m[3] == "1st rotational")
    assert abs(f_r / thesis - 1) < 0.005

    def antisym(res):
        return (_col(res, "span_forces_N", "alternator-crank") - _col(res, "span_forces_N", "crank-alternator")) / 2

    on, off = hybrid["rotational"], hybrid["rotational_off"]
    early, late = _window(on, 0.3, 0.5), _window(on, 0.8, 1.01)
    a = antisym(on)
    grow = _tone(on.t[late], a[late], f_r) / _tone(on.t[early], a[early], f_r)
    ratio = _tone(on.t[late], a[late], f_r) / _tone(off.t[late], antisym(off)[late], 0.8 * f_r)
    print(f"\n  rotational resonance at {f_r:.3f} Hz: antisymmetric span force {np.max(np.abs(a - a[0])):.4f} N "
          f"(growth {grow:.2f}, {ratio:.1f}x off resonance)")
    assert 1.9 < grow < 2.6
    assert abs(_dominant(on.t[late], a[late]) / f_r - 1) < 0.005
    assert ratio > 5


def test_steady_motion_near_the_critical_belt_speed(hybrid):
    """At 0.85 of the critical belt speed (v_c = sqrt(T lam / rhoA) = 70.6 m/s, where the span
    force T - rhoA v^2 / lam vanishes; the thesis' fixed-centre run-up reaches 0.98 v_c):

    * before the pulse (0-50 ms) the moving drive stays on its steady-motion statics: span
      tensions 0.1 N, span-node displacements 1 um;
    * after a 5 ms, 2 N pulse the loaded span vibrates at the gyroscopic modal analysis'
      1st transverse frequency (14.67 Hz, from 52.21 Hz at rest): 1 % (the record after the
      pulse holds 13 periods; two near-equal span modes 0.01 Hz apart share the peak);
    * both follow the moving string's law f(v) = f(0) (1 - v^2 / v_c^2) within 3 % (bending
      stiffness, EI = 0.034 N m^2, raises the frequency as the tension vanishes: +1.2 %).
    """
    res, sc, v, v_c = hybrid["critical"], hybrid["critical_scene"], hybrid["v"], hybrid["v_c"]
    assert abs(float(res.channels["belt_speed_m_s"][0]) / v - 1) < 1e-9
    st = hybrid["critical_modes"].statics
    pre = res.t < 0.05
    assert np.max(np.abs(res.channels["span_tensions_N"][pre] - st.span_tensions_N)) < 0.1
    assert np.max(np.abs(res.channels["node_displacements_m"][pre] - res.channels["node_displacements_m"][0])) < 1e-6
    lam = st.stretch
    # span force = tension - rhoA c^2 lam_chord: the sagging span's chord stretch differs from
    # the installation stretch by 1e-6
    np.testing.assert_allclose(res.channels["span_forces_N"][0],
                               st.span_tensions_N - float(sc.belt.rhoA) * v**2 / lam, rtol=1e-5)
    modes = hybrid["critical_modes"]
    assert modes.stable
    f_modal = next(f for f, lab in zip(modes.frequencies_hz, modes.labels) if lab.startswith("1st transverse"))
    after = res.t >= 0.1
    f_sim = _dominant(res.t[after], _node(res, "crank-alternator:3")[after])
    string = hybrid["f_t"] * (1 - (v / v_c) ** 2)
    print(f"\n  v = {v:.2f} m/s = 0.85 v_c: 1st transverse transient {f_sim:.3f} Hz, modal {f_modal:.3f} Hz, "
          f"moving string {string:.3f} Hz")
    assert abs(f_sim / f_modal - 1) < 0.01
    assert abs(f_modal / string - 1) < 0.03


def test_small_and_large_span_amplitudes(hybrid):
    """A 5 ms pulse on the lower span's middle at rest, undamped (rho_inf = 1):

    * 0.4 N (0.14 mm): the span rings at the modal analysis' 1st transverse frequency after the
      midpoint correction, 1e-3 (0.05 bin of the 0.9 s record);
    * 40 N (14 mm, 2 % of the span): stretching hardens the span: its frequency rises by the
      Kirchhoff-Carrier estimate for a string with fixed ends, df / f = (3/32) (EA_t / T)
      (pi a / L)^2 with a the ringing amplitude: within 0.7-1.4x of it (the pulleys are not
      fixed: their motion at twice the span frequency, above the 97 Hz rotational mode, adds
      to the span's tension swing); measured 5.5 % against 4.9 %;
    * energy after the pulse: constant within 1 % of what the pulse put in (the spans' axial
      modes are far from resolved at dt = 2e-4 s; measured 0.2 %); 100x the load, 100x the
      amplitude to 10 %: the motion stays bounded and near-linear in size.
    """
    small, large = hybrid["small"], hybrid["large"]
    after = small.t >= 0.1
    f_t = hybrid["f_t"]
    ws, wl = _node(small, "crank-alternator:3"), _node(large, "crank-alternator:3")
    f_small = _dominant(small.t[after], ws[after])
    f_large = _dominant(large.t[after], wl[after])
    a = signals.dominant_frequencies(large.t[after], wl[after], count=1, fmin=5.0)[0][1]
    sc = hybrid["large_scene"]
    st = hybrid["modes"].statics
    T0, lam = float(sc.belt.static_tension), st.stretch
    L = st.span_lengths_m[0]
    kc = 3 / 32 * _tangent_EA(sc, lam) / T0 * (math.pi * a / L) ** 2
    print(f"\n  pulses: 0.4 N -> {np.max(np.abs(ws[after])) * 1e3:.3f} mm at {f_small:.3f} Hz "
          f"(midpoint-corrected modal {_midpoint(f_t, small.meta['dt_s']):.3f}); 40 N -> {a * 1e3:.2f} mm at "
          f"{f_large:.3f} Hz: +{(f_large / f_small - 1) * 100:.2f} % (Kirchhoff-Carrier {kc * 100:.2f} %)")
    assert abs(f_small / _midpoint(f_t, small.meta["dt_s"]) - 1) < 1e-3
    assert 0.7 < (f_large / f_small - 1) / kc < 1.4
    assert 0.9 < np.max(np.abs(wl[after])) / np.max(np.abs(ws[after])) / 100 < 1.1
    E = np.asarray(_energy_fn(sc, st.inst)(jnp.asarray(large.y)))
    k = large.t >= 0.06
    put_in = E[k][0] - E[0]
    spread = (E[k].max() - E[k].min()) / put_in
    print(f"  energy put in {put_in:.4f} J, spread after the pulse {spread:.1e} of it")
    assert put_in > 0
    assert spread < 0.01


def test_free_drive_at_rest_under_gravity_stays_at_rest(hybrid):
    """A drive with no driven pulley, at rest under the belt's weight and without loads, must
    stay at rest: a closed belt loop turning rigidly does not change its potential energy.

    The map slides each span along its own line when the pulleys turn (as the thesis' eqs.
    4.37-4.38), which alone would move the spans' weight along their slopes (0.15 N along
    the belt here: a static residual of 0.015 N m on the crank's rotation, and the crank
    turning 0.06 deg in 50 ms); drive.body_forces counts the weight with the slides taken
    back (belt_weight_slide_moments), so neither happens.
    """
    sc = drive.canonical(hybrid["rest_scene"])
    st = hybrid["modes"].statics
    residual = np.asarray(eqx.filter_jit(drive.static_residual)(jnp.asarray(st.qi), sc, st.inst))
    res = hybrid["small"]
    pre = res.t < 0.05
    turned = np.max(np.abs(res.channels["pulley_rotations_deg"][pre] - res.channels["pulley_rotations_deg"][0]))
    print(f"\n  free drive under gravity: residual on the crank {residual[0]:.2e} N m, "
          f"turned {turned:.3f} deg in 50 ms")
    assert abs(residual[0]) < 1e-9 and turned < 1e-6


# =========================================================================== 7.2.2.4: hybrid tensioner


def _tensioner_hybrid_scene(arm_moment, span_force, frequency):
    """The 7.2.2.4 scene with a moment on the arm and a force on the idler-alternator span's
    middle (both always listed, so that every run shares one compiled model)."""
    text = substitute(
        scene_text("sim_tensioner_arm_resonance.toml"),
        ("amplitude_Nm = 0.01 ", f"amplitude_Nm = {float(arm_moment)!r} "),
        ("frequency_hz = 46.73 ", f"frequency_hz = {float(frequency)!r} "),
    )
    text += (f'\n[[span_load]]\nspan = "tensioner-alternator"\nnode = 2\namplitude_N = {float(span_force)!r}\n'
             f"frequency_hz = {float(frequency)!r}\n")
    return loads_scene(text)


@pytest.fixture(scope="module")
def tensioner_hybrid():
    """Thesis 7.2.2.4: the hybrid tensioner bench at rest driven at four natural frequencies
    of its own modal analysis, 0.75 s each: a moment on the arm at the upper span's and at the
    idler-alternator span's 1st transverse mode and at the 2nd rotational mode, and a force
    on the idler-alternator span at the tensioner mode."""
    base = _tensioner_hybrid_scene(0.0, 0.0, 1.0)
    modes = drive_modal.analyse_modes(base)
    st = modes.statics
    sc = drive.statics_scene(base)  # the scene as analyse_modes saw it: its compiled modes_at is reused
    qi = jnp.asarray(st.qi)
    lin = drive_modal.modes_at(sc, qi, st.inst, 0.0, False)  # M-orthonormal shapes
    names, order = drive.span_names(sc), list(sc.route.order)
    N = sc.model.elements_per_span

    def outputs(x):  # arm angle, alternator rotation (rad), middle-node normal displacements (m)
        phis, theta = drive.angles_and_arm(x, sc, st.inst)
        E, _ = drive.split_full(drive.full_coordinates(x, sc, st.inst), sc)

        def normal(span):
            s = names.index(span)
            tan = st.inst.span_tangent[s]
            return E[s, 4 * (N // 2) : 4 * (N // 2) + 2] @ jnp.stack([-tan[1], tan[0]])

        return jnp.stack([theta, phis[order.index("alternator")], normal("alternator-crank"),
                          normal("tensioner-alternator")])

    C = np.asarray(jax.jit(jax.jacfwd(outputs))(qi))  # compiled: 0.2 s against 5 s op by op
    pick = lambda label: next(i for i, lab in enumerate(modes.labels) if lab.startswith(label))  # noqa: E731
    arm_moment, span_force = 0.01, 0.05  # N m, N
    cases = dict(  # mode, arm moment, span force, output row
        upper=(pick("1st transverse alternator-crank"), arm_moment, 0.0, 2),
        idler_span=(pick("1st transverse tensioner-alternator"), arm_moment, 0.0, 3),
        rotational=(pick("2nd rotational"), arm_moment, 0.0, 1),
        tensioner=(pick("1st rotational (tensioner"), 0.0, span_force, 0),
    )
    dt = float(base.simulation.dt_s)
    out = dict(modes=modes, cases={})
    for name, (r, M, F, row) in cases.items():
        f = float(modes.frequencies_hz[r])
        f_drive = _midpoint(f, dt)
        phi = np.real(np.asarray(lin["shapes"])[:, r])
        Q = M * C[0] + F * C[3]  # generalised force of the moment on the arm / the normal force
        slope = abs(C[row] @ phi) * abs(phi @ Q) / (2 * 2 * math.pi * f)
        res = _simulate(_tensioner_hybrid_scene(M, F, f_drive), 0.75,
                        f"hybrid tensioner, {name}: {M} N m on the arm, {F} N on the span at {f:.3f} Hz")
        out["cases"][name] = dict(res=res, f=f, f_drive=f_drive, row=row, slope=slope, label=modes.labels[r])
    return out


def test_tensioner_excitations_put_the_drive_in_resonance(ref, tensioner_hybrid):
    """Thesis 7.2.2.4 (Figs. 7.81-7.84): rotational, longitudinal and transverse coordinates
    are coupled, so that

    * a moment on the tensioner at the upper span's 1st transverse frequency puts that span
      in resonance, although it does not touch the tensioner (the arm's swing stretches the
      spans at the idler, the pulleys pass it on as a tension swing of the upper span, and
      its sag under the belt's weight turns that into transverse motion);
    * the same at the idler-alternator span's 1st transverse frequency puts that span in
      resonance, and at the 2nd rotational frequency the alternator;
    * a force on the idler-alternator span at the tensioner's frequency puts the arm in
      resonance.

    Each response grows linearly at the rate the modal analysis gives for an undamped mode
    forced at its frequency, |c.phi| |phi.Q| / (2 omega) (phi M-orthonormal, Q the load's
    generalised force, c the output's row of the kinematic map): 1 %, between the windows
    0.15-0.45 s and 0.45-0.75 s (complex amplitudes, so that the constant
    off-resonant part drops out).  The load is driven at the frequency the midpoint rule shows for the mode,
    atan(pi f dt) / (pi dt).  The frequencies are this model's (arm at 46.8 deg, 455.6 N):
    the thesis' (at 498 N) are printed beside them.
    """
    rows = ref["tensioner_bench_stage2"]["modal"]["modes"]
    thesis = {"upper": rows[2][1], "idler_span": rows[3][1], "rotational": rows[5][1], "tensioner": rows[1][1]}
    print()
    for name, c in tensioner_hybrid["cases"].items():
        res, f = c["res"], c["f_drive"]
        x = [np.radians(res.channels["arm_angle_deg"]), np.radians(_col(res, "pulley_rotations_deg", "alternator")),
             _col(res, "node_displacements_m", "alternator-crank:2"),
             _col(res, "node_displacements_m", "tensioner-alternator:2")][c["row"]]
        early, late = _window(res, 0.15, 0.45), _window(res, 0.45, 0.75)
        z1, z2 = _complex_tone(res.t[early], x[early], f), _complex_tone(res.t[late], x[late], f)
        slope = abs(z2 - z1) / 0.3
        print(f"  {name}: {c['label']} at {c['f']:.3f} Hz (thesis {thesis[name]} Hz): response grows "
              f"{slope:.4e} per s (modal analysis {c['slope']:.4e}); amplitude {abs(z1):.3e} -> {abs(z2):.3e}")
        assert abs(slope / c["slope"] - 1) < 0.01, (name, slope, c["slope"])
        assert 1.9 < abs(z2) / abs(z1) < 2.1  # from rest: the window means grow as 0.3 s : 0.6 s
        assert res.meta["slack_spans"] == []
