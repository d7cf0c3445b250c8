"""Whole drives: statics, modal analysis and Campbell diagrams against the thesis (ch. 7).

Numbers come from ../shared/reference/thesis_reference.json (the ``ref`` fixture).
Compiled functions are shared: scenes that differ only in numbers reuse one
compilation (``drive.canonical``), so the three bench tensions cost one compile.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import campbell, drive, drive_modal, statics
from beltjax.scene import load_scene, loads_scene

SCENES = pathlib.Path(__file__).resolve().parents[1] / "scenes"
ORD = re.compile(r"^(\d+)(st|nd|rd|th) (transverse|longitudinal|rotational)")


def _bench(T):
    return load_scene(SCENES / f"two_pulley_T{T}.toml")


def _with(scene, **model):
    return dataclasses.replace(scene, model=dataclasses.replace(scene.model, **model))


@pytest.fixture(scope="module")
def bench_modes(ref):
    cases = ref["two_pulley_bench"]["modal"]["cases"]
    return {c["T"]: (c, drive_modal.analyse_modes(_bench(c["T"]))) for c in cases}


def _parse(label):
    m = ORD.match(label)
    return (int(m.group(1)), m.group(3)) if m else (None, label)


def _ours(result, order, kind):
    """Frequencies of our modes labelled '<order> <kind>' (Hz)."""
    return [f for f, lab in zip(result.frequencies_hz, result.labels) if _parse(lab) == (order, kind)]


# --------------------------------------------------------------------------- two-pulley bench


def test_repeated_pairs_are_each_one_spans_mode(bench_modes):
    """Both spans carry one tension, so their transverse frequencies come in repeated pairs, whose
    eigenspace eigh returns in an arbitrary basis: analyse_modes turns it so that each mode is one
    span's (>= 0.999 of its energy in one span) and no label names two spans.  (The longitudinal
    modes are not repeated: the pulleys couple the spans into a symmetric and an antisymmetric
    mode, 714.1 and 727.1 Hz at 200 N, rightly labelled with both spans.)"""
    for T, (_, res) in bench_modes.items():
        f = res.frequencies_hz
        names = drive.span_names(_bench(T))
        repeated = [m for m in range(1, len(f)) if min(abs(f[m] - f[m - 1]), abs(f[m] - f[min(m + 1, len(f) - 1)])
                                                       if m + 1 < len(f) else abs(f[m] - f[m - 1])) <= 1e-6 * f[m]]
        assert len(repeated) >= 40, T
        for m in repeated:
            lab = res.labels[m]
            assert " + " not in lab and "transverse" in lab, (T, m, lab)
            e = np.array([res.energy_shares[f"{s} transverse"][m] for s in names])
            assert e.max() >= 0.999, (T, m, lab, e)


def test_bench_mode_count_and_rigid_mode(bench_modes):
    # 16 elements per span: 142 full coordinates (thesis), 130 independent ones
    for T, (_, res) in bench_modes.items():
        assert res.n_independent == 130
        assert drive.n_full(_bench(T)) == 142
        assert res.labels[0] == "rigid body" and res.frequencies_hz[0] == 0.0
        assert res.frequencies_hz[1] > 20.0


def test_bench_transverse_frequencies_match_measurement(bench_modes):
    """Every measured transverse frequency of Tables 7.2, 7.4 and 7.6 within 1 %."""
    checked = 0
    for T, (case, res) in bench_modes.items():
        for num, theory, measured, shape in case["modes"]:
            order, kind = _parse(shape)
            if kind != "transverse" or measured is None:
                continue
            ours = _ours(res, order, "transverse")
            assert len(ours) == 2, (T, shape, ours)  # one per span (equal tensions)
            assert abs(ours[0] - ours[1]) < 1e-6 * ours[0]
            assert abs(ours[0] / measured - 1) < 0.01, (T, shape, ours[0], measured)
            assert abs(ours[0] / theory - 1) < 0.005, (T, shape, ours[0], theory)
            checked += 1
    assert checked == 27


def test_bench_rotational_and_longitudinal_modes(bench_modes):
    """1st rotational within 1 % of the thesis' theory and at the same mode number;
    longitudinal modes within 2 %."""
    for T, (case, res) in bench_modes.items():
        for num, theory, measured, shape in case["modes"]:
            order, kind = _parse(shape)
            if kind == "rotational":
                ours = _ours(res, order, "rotational")
                assert len(ours) == 1
                assert abs(ours[0] / theory - 1) < 0.01, (T, ours[0], theory)
                assert res.labels.index(f"{shape} (alternator, crank)") + 1 == num
            elif kind == "longitudinal":
                ours = sorted(_ours(res, order, "longitudinal"))
                assert ours, (T, shape)
                assert abs(ours[0] / theory - 1) < 0.02, (T, shape, ours[0], theory)


def test_bench_static_hub_reactions(ref):
    """Table 7.1: alternator bearing reaction within 2 % of the thesis' theory.

    X_A is printed for T = 200, 400 and 600 N; 300 and 500 N use the linear
    interpolation between them (the reaction depends on X_A only through the
    tiny span inclination change).
    """
    table = ref["two_pulley_bench"]["static_reactions_alternator_bearing"]["theory"]
    cases = ref["two_pulley_bench"]["modal"]["cases"]
    xa = np.interp([r[0] for r in table], [c["T"] for c in cases], [c["X_A"] for c in cases])
    base = _bench(200)
    for (T, Fx, Fy), x in zip(table, xa):
        alt = base.pulley("alternator")
        sc = eqx.tree_at(lambda s: (s.belt.static_tension, s.pulleys[1].center), base,
                         (jnp.asarray(T, float), jnp.array([x, float(alt.center[1])])))
        res = statics.analyse_statics(sc)
        hub = res.hub_forces_N["alternator"]
        assert abs(hub[0] / Fx - 1) < 0.02, (T, hub, Fx)
        assert abs(hub[1] / Fy - 1) < 0.02, (T, hub, Fy)
        np.testing.assert_allclose(res.span_tensions_N, T, rtol=1e-6)
        # the crank carries the opposite force; the belt fits round both pulleys
        np.testing.assert_allclose(res.hub_forces_N["crank"], -hub, rtol=1e-9)


def test_static_tension_and_length_agree():
    """Giving the length that static_tension produced gives back the tension."""
    text = (SCENES / "two_pulley_T400.toml").read_text()
    r1 = statics.analyse_statics(loads_scene(text))
    old = "static_tension = 400.0"
    assert old in text
    r2 = statics.analyse_statics(loads_scene(text.replace(old, f"length = {r1.belt_length_m!r}")))
    np.testing.assert_allclose(r2.span_tensions_N, r1.span_tensions_N, rtol=1e-9)
    # the thesis' nominal 1.8 m is not the unstretched length of the model
    assert 1.790 < r1.belt_length_m < 1.796


# --------------------------------------------------------------------------- tensioner bench


@pytest.fixture(scope="module")
def tensioner_modes():
    return drive_modal.analyse_modes(load_scene(SCENES / "tensioner_bench_stage2.toml"))


def test_tensioner_statics_is_an_equilibrium(tensioner_modes):
    """Spring moment balances the belt's moment on the arm; free pulleys equalise the tensions."""
    sc = load_scene(SCENES / "tensioner_bench_stage2.toml")
    st = tensioner_modes.statics
    T = st.span_tensions_N
    np.testing.assert_allclose(T, T.mean(), rtol=1e-8)
    th = math.radians(st.tensioner_angle_deg)
    t = sc.tensioner
    r = np.asarray(t.idler_center(th) - t.pivot)
    F = st.hub_forces_N["tensioner"]
    belt_moment = r[0] * F[1] - r[1] * F[0]
    assert abs(belt_moment + st.spring_moment_Nm) < 1e-8 * abs(st.spring_moment_Nm)
    # the spring moment equals -k (theta - theta0)
    k, th0 = float(t.spring_stiffness), math.radians(float(t.spring_preload_deg))
    assert abs(st.spring_moment_Nm + k * (th - th0)) < 1e-9


def test_tensioner_bench_against_thesis(ref, tensioner_modes):
    """What matches and what cannot: see README "Tensioner bench".

    The upper span T1 (alternator-crank) does not touch the tensioner: its
    frequencies depend only on the tension, and they match the measurement
    within 2 %.  The printed static state (497 N at 46.8 deg) is not an
    equilibrium of the printed spring (k = 21.14 N m/rad, theta_0 = 94.5 deg)
    on this layout: at 46.8 deg the spring holds only ~456 N (checked here),
    so the arm angle and the spans touching the idler cannot match the thesis
    with the published inputs; the model follows the published inputs.
    """
    res = tensioner_modes
    rows = ref["tensioner_bench_stage2"]["modal"]["modes"]
    t1 = [(r[2], r[3]) for r in rows if r[3].endswith("(T1)") and r[2] is not None]
    for measured, shape in t1[:3]:
        order = int(shape.split()[0][:-2])
        ours = [f for f, lab in zip(res.frequencies_hz, res.labels) if lab == f"{shape.split(' (')[0]} alternator-crank"]
        assert len(ours) == 1, (shape, res.labels[:12])
        assert abs(ours[0] / measured - 1) < 0.02, (shape, ours[0], measured)
        assert order >= 1
    # the printed (T, theta) pair violates the spring's moment balance by > 5 %
    sc = load_scene(SCENES / "tensioner_bench_stage2.toml")
    st = ref["tensioner_bench_stage2"]["static"]
    th = jnp.radians(st["arm_angle_deg_rotational_model"])
    _, arm, _ = statics._arm_terms(th, sc)
    t = sc.tensioner
    T_spring = float(t.spring_stiffness * (jnp.radians(t.spring_preload_deg) - th) / -arm)
    assert T_spring < 0.95 * st["T_theory"], T_spring
    # ... yet the thesis' theoretical alternator bearing force is this layout's at 46.8 deg: its
    # direction is the bisector of the two spans there (measured 0.003 deg apart; at the model's
    # equilibrium, 56.4 deg, 0.8 deg), and its magnitude is 2 T sin(wrap / 2) with T = 497 N
    # (0.06 %).  So geometry and angle frame agree with the thesis; what differs is the spring
    # moment: T_theory x arm(46.8 deg) = 19.2 N m against k (theta_0 - theta) = 17.6 N m.
    F = np.asarray(st["alternator_bearing_theory"])

    def bisector(theta_deg):
        g = sc.geometry(jnp.radians(theta_deg))
        i = sc.route.order.index("alternator")
        u = np.asarray(g.span_tangent[i] - g.span_tangent[i - 1])  # belt pull on the alternator / T
        return u, math.degrees(math.atan2(F[0] * u[1] - F[1] * u[0], F @ u))

    u, miss = bisector(st["arm_angle_deg_rotational_model"])
    _, miss_eq = bisector(tensioner_modes.statics.tensioner_angle_deg)
    print(f"\n  thesis bearing force vs span bisector: {miss:+.3f} deg at 46.8 deg, {miss_eq:+.3f} deg at "
          f"{tensioner_modes.statics.tensioner_angle_deg:.2f} deg; |F| / (T |u|) = "
          f"{np.linalg.norm(F) / (st['T_theory'] * np.linalg.norm(u)):.4f}")
    assert abs(miss) < 0.1 and abs(miss_eq) > 0.5
    assert abs(np.linalg.norm(F) / (st["T_theory"] * np.linalg.norm(u)) - 1) < 0.005
    M_thesis = st["T_theory"] * float(-arm)
    assert M_thesis > 1.05 * float(t.spring_stiffness * (jnp.radians(t.spring_preload_deg) - th)), M_thesis
    # the thesis' installation (Simulation 1, 7.2.1.2) says the same: the arm held where the belt
    # fits unstretched (44.3 deg, no belt force) needs M_ti = 20.6 N m, against the printed spring's
    # k (theta_0 - theta) = 18.5 N m there: at both angles its model's spring gave 9-11 % more
    # moment than the printed one (as k = 23.1-23.5 N m/rad with theta_0 = 94.5 deg, or theta_0 =
    # 98.8-100.1 deg with k = 21.14).  (A stiffer spring alone does not restore 46.8 deg here: the
    # belt that fits unstretched at 44.3 deg gains only 1.7 mm of path by 46.8 deg; README.)
    installation = ref["tensioner_bench_stage2"]["installation"]
    th_i = jnp.radians(installation["belt_fits_unstretched_at_arm_angle_deg"])
    excess_i = installation["minimum_installation_moment_Nm"] / float(
        t.spring_stiffness * (jnp.radians(t.spring_preload_deg) - th_i))
    excess_eq = M_thesis / float(t.spring_stiffness * (jnp.radians(t.spring_preload_deg) - th))
    print(f"  thesis spring moment / printed spring: {excess_i:.3f} at the installation (44.3 deg), "
          f"{excess_eq:.3f} at the equilibrium (46.8 deg)")
    assert 1.05 < excess_i < 1.2 and abs(excess_i / excess_eq - 1) < 0.03
    # labels: a tensioner rotational mode is the lowest flexible mode, as in Table 7.9
    assert res.labels[1].startswith("1st rotational (tensioner")


# --------------------------------------------------------------------------- convergence and gradients


def test_mesh_convergence_of_drive_frequencies():
    """Frequencies converge with elements per span: errors against 16 elements fall."""
    base = drive.canonical(_bench(600))
    sel = np.arange(1, 12)
    ref16 = np.asarray(jax.jit(drive_modal.frequencies)(base, 0.0))[sel]
    errs = []
    for n in (4, 8):
        f = np.asarray(jax.jit(drive_modal.frequencies)(_with(base, elements_per_span=n), 0.0))[sel]
        errs.append(np.max(np.abs(f / ref16 - 1)))
    assert errs[1] < errs[0] / 4, errs  # at least second-order in h (ANCF cubic: ~h^4)
    assert errs[1] < 2e-3, errs


def test_gradients_match_finite_differences():
    """d(frequencies, tensions, arm angle)/d(EA, EI, alternator x, pivot x) by the implicit
    function theorem equal central differences (tensioner bench, 4 elements per span)."""
    sc = drive.canonical(_with(load_scene(SCENES / "tensioner_bench_stage2.toml"), elements_per_span=4))
    yc, py = float(sc.pulleys[1].center[1]), float(sc.tensioner.pivot[1])

    def outputs(p):
        s = eqx.tree_at(
            lambda s: (s.belt.EA, s.belt.EI, s.pulleys[1].center, s.tensioner.pivot), sc,
            (p[0], p[1], jnp.stack([p[2], yc]), jnp.stack([p[3], py])),
        )
        m = drive_modal.at_speed(s, 0.0)  # one statics (implicit differentiation) for every output
        f, qi, inst = m.freqs, m.qi, m.inst
        T = drive.span_tensions(drive.full_coordinates(qi, s, inst), s, inst)
        _, th = drive.angles_and_arm(qi, s, inst)
        return jnp.concatenate([f[1:5], T[:1], th[None]])

    p0 = jnp.array([111190.0, 0.034, float(sc.pulleys[1].center[0]), float(sc.tensioner.pivot[0])])
    # one compiled function gives the Jacobian and (its auxiliary output) the value for the differences
    both = jax.jit(jax.jacfwd(lambda p: (lambda y: (y, y))(outputs(p)), has_aux=True))
    J = np.asarray(both(p0)[0])
    fo = lambda p: both(p)[1]  # noqa: E731
    for k, h in enumerate([10.0, 1e-4, 1e-6, 1e-6]):
        e = np.zeros(4)
        e[k] = h
        fd = (np.asarray(fo(p0 + e)) - np.asarray(fo(p0 - e))) / (2 * h)
        # the Newton tolerance (1e-11 m) puts ~1e-5 of noise into the differences of the
        # weakly sensitive entries: absolute floor 1e-5 of the column's largest entry
        tol = 1e-4 * np.abs(fd) + 1e-5 * np.max(np.abs(fd))
        assert np.all(np.abs(J[:, k] - fd) <= tol), (k, J[:, k], fd)
        assert np.max(np.abs(fd)) > 0


# --------------------------------------------------------------------------- Campbell


def test_campbell_transport_lowers_transverse_frequencies():
    """With transport the transverse frequencies fall with speed like a moving string's
    sqrt(1 - (v/c)^2)-ish trend; the rotational mode stays; crossings lie on the order lines."""
    sc = _with(_bench(200), effects=("transport",))
    rpm = np.array([0.0, 1000.0, 2000.0])
    res = campbell.analyse_campbell(sc, rpm, orders=(1.0, 2.0), n_modes=9)
    f = res.frequencies_hz
    assert res.stable.all()
    assert np.all(np.diff(f[:, 1]) < 0)  # 1st transverse falls with speed
    v = np.asarray(drive.belt_speed(sc, jnp.asarray(rpm)))
    T, rhoA = 200.0, float(sc.belt.rhoA)
    string = (1 - rhoA * v**2 / T)  # moving string: f(v)/f(0) = 1 - v^2 rhoA / T
    assert np.allclose(f[:, 1] / f[0, 1], string, rtol=0.01), (f[:, 1] / f[0, 1], string)
    rot = [i for i, lab in enumerate(res.labels) if "rotational" in lab][0]
    assert np.allclose(f[:, rot], f[0, rot], rtol=0.02)
    for c in res.crossings:
        assert abs(c["frequency_hz"] - c["order"] * c["rpm"] / 60) < 1e-9


def test_campbell_matches_single_modal_analysis():
    sc = _with(_bench(200), effects=("transport",))
    res = campbell.analyse_campbell(sc, np.array([0.0, 1500.0]), n_modes=9)
    single = drive_modal.analyse_modes(sc, float(drive.belt_speed(sc, 1500.0)))
    # columns are tracked modes (at least the 9 lowest at each speed): sorted, they are the modal analysis'
    np.testing.assert_allclose(np.sort(res.frequencies_hz[1])[:9], single.frequencies_hz[:9], rtol=1e-8, atol=1e-8)
    # labels of the complex (travelling-wave) modes at speed: standing-wave nodes counted
    orders = [_parse(lab)[0] for lab in single.labels if "transverse" in lab][:16]
    assert orders == [k for k in range(1, 9) for _ in (0, 1)], single.labels[:20]


# --------------------------------------------------------------------------- bad drives


TWO = (SCENES / "two_pulley_T200.toml").read_text()


@pytest.mark.parametrize(
    "old,new,match",
    [
        ("static_tension = 200.0", "length = 1.60", "belt too short to fit"),
        ("static_tension = 200.0", "static_tension = 9000.0", "belt too short to fit"),
    ],
)
def test_bad_belt_is_a_one_line_error(old, new, match):
    assert old in TWO
    sc = loads_scene(TWO.replace(old, new))
    with pytest.raises(statics.StaticsError, match=match) as e:
        statics.analyse_statics(sc)
    assert "\n" not in str(e.value)


def test_tensioner_belt_too_long_or_short():
    text = (SCENES / "tensioner_bench_stage2.toml").read_text()
    old = "length = 1.792939915"
    assert old in text
    with pytest.raises(statics.StaticsError, match="too long") as e:
        statics.analyse_statics(loads_scene(text.replace(old, "length = 1.95")))
    assert str(e.value).startswith("belt.length:")
    with pytest.raises(statics.StaticsError, match="belt.length: belt too short to fit") as e:
        statics.analyse_statics(loads_scene(text.replace(old, "length = 1.70")))
    assert "\n" not in str(e.value)


# --------------------------------------------------------------------------- rotational fidelity


def _rotational(text):
    return loads_scene(text.replace('fidelity = "ancf"', 'fidelity = "rotational"'))


def test_rotational_fidelity_shares_the_statics_and_finds_the_torsional_mode(ref):
    """The Newton-Euler fidelity (spans as massless axial springs, same kinematic map):
    at rest its statics equal the hybrid model's; its torsional mode lies within 2 % of the
    thesis' rotational model (96.7 Hz free, 81.8 Hz with the crank prescribed, T = 600 N).
    Ours sits 1.3-1.9 % higher: the spring follows the Green-Lagrange law of the ANCF element
    (tangent stiffness EA (3 lam^2 - 1)/2, 1.6 % above the thesis' linear EA/L at 600 N) and
    the wrapped belt adds to the pulley inertias."""
    text = (SCENES / "two_pulley_T600.toml").read_text()
    checks = ref["two_pulley_bench"]["rotational_model_checks"]
    rot = drive_modal.analyse_modes(_rotational(text))
    hyb = statics.analyse_statics(load_scene(SCENES / "two_pulley_T600.toml"))
    np.testing.assert_allclose(rot.statics.span_tensions_N, hyb.span_tensions_N, rtol=1e-9)
    np.testing.assert_allclose(rot.statics.hub_forces_N["alternator"], hyb.hub_forces_N["alternator"], rtol=1e-9)
    assert rot.n_independent == 2 and rot.labels == ["rigid body", "1st rotational (alternator, crank)"]
    assert abs(rot.frequencies_hz[1] / checks["free_free_torsional_frequency_hz"] - 1) < 0.02
    driven = drive_modal.analyse_modes(_rotational(text.replace("driven = false ", "driven = true ")))
    assert driven.n_independent == 1
    assert abs(driven.frequencies_hz[0] / checks["crank_prescribed_torsional_frequency_hz"] - 1) < 0.02


def test_reduced_equations_agree_with_the_linearisation():
    """drive.reduced_system (M_ii = J^T M J, F_ii = J^T (F - M gamma), the equations the
    transients integrate) gives the modal M, G and the static residual (tensioner bench:
    a nonlinear kinematic map through the arm)."""
    sc = drive.canonical(_with(load_scene(SCENES / "tensioner_bench_stage2.toml"), elements_per_span=4))
    v = 15.0

    @jax.jit
    def check(sc):
        qi, inst, _ = statics.equilibrium(sc, speed=v)
        qi = qi.at[3].add(0.01)  # off equilibrium: the arm turned
        z = jnp.zeros_like(qi)
        M, F = drive.reduced_system(qi, z, sc, inst, v)
        G = -jax.jacfwd(lambda w: drive.reduced_system(qi, w, sc, inst, v)[1])(z)
        Ml, Gl, _ = drive_modal.linearise(qi, sc, inst, v)
        return M, F, G, Ml, Gl, drive.static_residual(qi, sc, inst, v)

    M, F, G, Ml, Gl, R = check(sc)
    np.testing.assert_allclose(M, Ml, rtol=1e-12, atol=1e-12 * np.abs(Ml).max())
    np.testing.assert_allclose(F, R, rtol=1e-10, atol=1e-10 * np.abs(R).max())
    np.testing.assert_allclose(G, Gl, rtol=1e-10, atol=1e-10 * np.abs(Gl).max())
    assert np.abs(R).max() > 1.0  # a real residual off equilibrium


def test_a_drive_whose_every_pulley_is_driven():
    """Every pulley driven (a motor and a prescribed load, no tensioner): the rotational model has
    no coordinate, its statics is the installed state and its modal analysis a one-line
    refusal naming model.fidelity; the hybrid model's spans still vibrate (no rigid mode to
    take out: the belt cannot slide as a whole)."""
    from beltjax.errors import BeltjaxError

    txt = (pathlib.Path(__file__).resolve().parents[1] / "scenes" / "two_pulley_T200.toml").read_text()
    txt = txt.replace("driven = false", "driven = true").replace("inertia = 1.7019e-3 ", "driven = true\n"
                                                                 "inertia = 1.7019e-3 ", 1)
    txt = re.sub(r"elements_per_span = \d+", "elements_per_span = 2", txt)
    rot = loads_scene(txt.replace('fidelity = "ancf"', 'fidelity = "rotational"'))
    assert drive.n_independent(rot) == 0
    r = statics.analyse_statics(rot)
    assert np.allclose(r.span_tensions_N, 200.0, rtol=1e-12)
    with pytest.raises(BeltjaxError, match="no modes") as e:
        drive_modal.analyse_modes(rot)
    assert e.value.key == "model.fidelity"
    m = drive_modal.analyse_modes(loads_scene(txt))
    assert m.stable and len(m.frequencies_hz) == drive.n_independent(loads_scene(txt))
    assert np.all(np.asarray(m.frequencies_hz) > 1.0)  # no rigid mode among them
