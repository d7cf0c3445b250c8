"""Modes tracked across speeds (beltjax.mode_tracking, beltjax.campbell): a label, a colour and a
crossing follow the mode (its shape), not its rank in frequency.

Synthetic cases first (numpy, no compilation): a crossing, a veering resolved by the steps and
one that is not, a repeated pair whose basis the solver returns at random, gaps.  Then the
two-pulley bench (6 elements per span, transport): the crossing that sorted columns label
"1st rotational" is a transverse mode, by the tracked curves and by an independent modal
analysis at that speed; and the tensioner bench (4 elements per span, a softer spring): tracked
curves are continuous through a crossing, and a veering is reported.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import numpy as np
import pytest

from beltjax import campbell, drive, drive_modal, mode_tracking, parameters
from beltjax.scene import load_scene
from _scenes import SCENES

RNG = np.random.default_rng(20)


def _unit(n, *idx):
    v = np.zeros(n, complex)
    v[list(idx)] = 1.0
    return v / np.linalg.norm(v)


def _phase(v):
    """A random complex factor: the solver's eigenvectors have arbitrary phase and scale."""
    return v * RNG.uniform(0.5, 2.0) * np.exp(1j * RNG.uniform(0, 2 * np.pi))


def _steps(states):
    """Track a list of steps, each (freqs, shapes as columns) given in any order: sorted here as a
    solver returns them."""
    F, W = [], []
    for f, X in states:
        o = np.argsort(f)
        F.append(np.asarray(f)[o])
        W.append(np.stack([_phase(X[:, j]) for j in o], axis=1))
    return mode_tracking.track(np.array(F), np.array(W)), np.array(F)


# --------------------------------------------------------------------------- synthetic


def test_crossing_modes_keep_their_curves():
    """Two modes whose frequencies cross (they swap places in sorted order) with a third above."""
    s = np.linspace(0.0, 10.0, 21)
    e = [_unit(5, 0), _unit(5, 1, 2), _unit(5, 3)]
    states = [(np.array([10 + x, 20 - x, 40.0]), np.stack(e, axis=1)) for x in s]
    t, F = _steps(states)
    assert np.any(np.diff(np.argsort([st[0] for st in states], axis=1)[:, 0]))  # sorted order swaps
    np.testing.assert_allclose(t.freqs[:, 0], 10 + s)  # curve 0: mode A throughout
    masks = mode_tracking.rank_masks(t, [0], 3)  # where mode A sits in each step's sorted order
    np.testing.assert_array_equal(np.flatnonzero(masks[:, 1]), np.flatnonzero(10 + s > 20 - s))
    np.testing.assert_allclose(F[masks], 10 + s)
    np.testing.assert_allclose(t.freqs[:, 1], 20 - s)
    np.testing.assert_allclose(t.freqs[:, 2], 40.0)
    assert t.freqs.shape[1] == 3 and np.nanmin(t.mac) > 1 - 1e-12


def _veering(g, s):
    """Two coupled modes: K = [[10 + s, g], [g, 20 - s]] (eigenvalues avoid crossing at s = 5 by
    2 g), plus an uncoupled third; returns (freqs, shapes) per s."""
    out = []
    for x in s:
        lam, V = np.linalg.eigh(np.array([[10 + x, g], [g, 20 - x]]))
        X = np.zeros((4, 3), complex)
        X[:2, :2] = V
        X[3, 2] = 1.0
        out.append((np.array([lam[0], lam[1], 50.0]), X))
    return out


def test_veering_resolved_by_the_steps_follows_the_branch_and_changes_label():
    """Strong coupling (gap 2 Hz, shapes exchange over ~4 Hz of s, steps of 0.25): each curve
    follows its branch, the frequency stays continuous and the shape (label) changes."""
    s = np.linspace(0.0, 10.0, 41)
    t, F = _steps(_veering(1.0, s))
    np.testing.assert_allclose(t.freqs[:, 0], F[:, 0])  # the lower branch, continuous
    assert np.max(np.abs(np.diff(t.freqs[:, 0]))) < 0.3
    assert np.nanmin(t.mac) > 0.9
    # labels from the shapes: "A" while mostly coordinate 0; the lower curve becomes "B"
    W = [_veering(1.0, [x])[0][1] for x in s]
    labels = [["1st transverse A" if abs(W[k][0, j]) ** 2 > 0.5 else "1st transverse B" for j in t.index[k]]
              for k in range(len(s))]
    changes = mode_tracking.label_changes([row[0] for row in labels], s)
    assert [(c["from"], c["to"]) for c in changes] == [("1st transverse A", "1st transverse B")]
    assert 4.5 <= changes[0]["at"] <= 5.5


def test_veering_within_one_step_follows_the_shape():
    """Weak coupling (gap 0.02 Hz): the shapes exchange within one step; each curve keeps its
    shape and crosses the small gap, as a crossing would.  A step right at the veering's centre
    (shapes half and half) cannot tell the two apart: its MAC says so (below UNCERTAIN_MAC)."""
    s = np.linspace(0.25, 10.25, 21)
    t, F = _steps(_veering(0.01, s))
    np.testing.assert_allclose(t.freqs[:, 0], 10 + s, atol=0.02)
    np.testing.assert_allclose(t.freqs[:, 1], 20 - s, atol=0.02)
    assert np.nanmin(t.mac) > 0.99
    t, _ = _steps(_veering(0.01, s - 0.25))
    assert 0.45 < np.nanmin(t.mac) < mode_tracking.UNCERTAIN_MAC


def test_repeated_pair_is_matched_as_a_subspace():
    """Two modes with equal frequencies whose eigenvectors the solver returns as a random basis of
    their plane at each step (and, once, two columns per mode, complex multiples of each other),
    while a third mode crosses them: the tracked pair keeps its own shapes and the third mode
    its curve."""
    n, s = 6, np.linspace(0.0, 10.0, 11)
    a, b, c = _unit(n, 0, 1), _unit(n, 2, 3), _unit(n, 4)
    F, W, owners = [], [], []
    for x in s:
        Q, _ = np.linalg.qr(RNG.standard_normal((2, 2)) + 1j * RNG.standard_normal((2, 2)))
        pair = np.stack([a, b], axis=1) @ Q
        f = np.array([30.0, 30.0, 25.0 + x])
        o = np.argsort(f, kind="stable")
        cols = [pair[:, 0], pair[:, 1], c]
        X = np.stack([_phase(cols[j]) for j in o] + [_phase(cols[j]) for j in o], axis=1)
        F.append(f[o])
        W.append(X)
        owners.append(np.concatenate([np.arange(3), np.arange(3)]))
    t = mode_tracking.track(np.array(F), np.array(W), owner=np.array(owners))
    third = [j for j in range(3) if np.allclose(t.freqs[:, j], 25.0 + s)]
    assert len(third) == 1
    pair_curves = [j for j in range(3) if j != third[0]]
    np.testing.assert_allclose(t.freqs[:, pair_curves], 30.0)
    assert np.nanmin(t.mac) > 1 - 1e-9  # the pair's curves keep their shapes exactly


def test_gaps_and_modes_entering_the_window():
    """Steps without modes (unstable) are gaps; a mode that comes from above the computed window
    starts its own curve instead of taking over another."""
    n = 4
    e = [_unit(n, i) for i in range(n)]
    F, W, valid = [], [], []
    for k in range(8):
        high = 61.0 - 8.0 * k  # mode 3 falls into the two-mode window from above
        f = np.array([20.0, 30.0, high])
        o = np.argsort(f)[:2]
        F.append(f[o])
        W.append(np.stack([e[j] for j in o], axis=1))
        valid.append(k not in (2, 3))
    t = mode_tracking.track(np.array(F), np.array(W), valid=np.array(valid))
    assert np.all(np.isnan(t.freqs[[2, 3]]))
    np.testing.assert_allclose(t.freqs[[0, 1, 4, 5], 0], 20.0)
    assert t.freqs.shape[1] == 3  # the mode that entered has its own curve
    np.testing.assert_allclose(t.freqs[4:, 2], (61.0 - 8.0 * np.arange(8))[4:])
    assert np.all(np.isnan(t.freqs[:4, 2])) and np.all(np.isnan(t.freqs[4:, 1]))  # mode 2 left the window
    assert list(mode_tracking.reported(t, 1)) == [0, 2]  # the lowest mode at some step


def test_labels_follow_kind_and_member_not_ordinals():
    """Along a curve the ordinal is not compared (a travelling mode's half-waves blur at speed), a
    one-step excursion to another kind is not a change, a change of kind is."""
    labels = ["5th transverse a-b", "5th transverse a-b", "3rd transverse a-b", None, "1st rotational (x)",
              "1st transverse a-b + c-d", "2nd rotational (x, y)", "2nd rotational (x, y)"]
    followed = mode_tracking.follow_labels(labels)
    assert followed[:3] == ["5th transverse a-b"] * 3 and followed[3] is None
    assert followed[4:6] == ["5th transverse a-b"] * 2
    assert followed[6:] == ["2nd rotational (x, y)"] * 2
    changes = mode_tracking.label_changes(labels, np.arange(8.0) * 100)
    assert [(c["from"], c["to"], c["after"], c["at"]) for c in changes] == [
        ("5th transverse a-b", "2nd rotational (x, y)", 500.0, 600.0)]


# --------------------------------------------------------------------------- the two-pulley bench


def test_orders_beyond_the_schema_are_refused_naming_the_order():
    """An order outside fluctuation.order's (0, 1000] (1e300 listed crossings "order 1e+300x" with
    overflow warnings): a one-line error naming orders[i], before any computation."""
    import warnings

    from beltjax.errors import BeltjaxError

    sc = load_scene(SCENES / "two_pulley_T200.toml")
    for orders, key in (((2.0, 1e300), "orders[1]"), ((1000.5,), "orders[0]")):
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            with pytest.raises(BeltjaxError) as exc:
                campbell.analyse_campbell(sc, [0.0, 100.0], orders=orders)
        assert exc.value.key == key and str(exc.value).startswith(f"{key}: must lie in [0, 1000]"), str(exc.value)


def test_crossings_of_huge_order_lines_do_not_overflow():
    """The sign test of a crossing never multiplies two differences (1e300 x 1e300 overflowed)."""
    import warnings

    rpm = np.array([0.0, 50.0, 100.0])
    freqs = np.array([[10.0], [10.0], [10.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        got = campbell.crossings(rpm, freqs, orders=(1e300, 6.0))
    assert [(c["order"], round(c["rpm"], 6)) for c in got] == [(1e300, 0.0), (6.0, 100.0)]


def _mesh(scene, n):
    return eqx.tree_at(lambda s: s.model, scene, dataclasses.replace(scene.model, elements_per_span=n))


RPM = np.arange(0.0, 3001.0, 50.0)


@pytest.fixture(scope="module")
def bench():
    """The two-pulley bench at T = 200 N with transport, 6 elements per span, 0-3000 rpm."""
    sc = _mesh(load_scene(SCENES / "two_pulley_T200.toml"), 6)
    assert sc.model.has("transport")
    return sc, campbell.analyse_campbell(sc, RPM, n_modes=12)


def _sorted_crossings(res, n=12):
    """What sorted columns gave: each rank labelled by its mode at the lowest speed."""
    F = np.sort(np.where(np.isfinite(res.frequencies_hz), res.frequencies_hz, np.inf), axis=1)[:, :n]
    order = np.argsort(res.frequencies_hz[0])
    rank_labels = [res.labels[j] for j in order[:n]]
    return campbell.crossings(res.rpm, F, res.orders, rank_labels)


def test_bench_crossing_of_the_rotational_rank_is_a_transverse_mode(bench):
    sc, res = bench
    old = [c for c in _sorted_crossings(res) if c["order"] == 2.0 and c["label"].startswith("1st rotational")]
    rot = [j for j, lab in enumerate(res.labels) if lab.startswith("1st rotational")]
    assert len(rot) == 1
    f_rot = res.frequencies_hz[:, rot[0]]
    assert np.nanmax(f_rot) - np.nanmin(f_rot) < 0.1  # the rotational mode stays (~96.3 Hz)
    true_rot_rpm = 30.0 * f_rot[-1]  # where 2x meets ~96.2 Hz
    wrong = [c for c in old if c["rpm"] < true_rot_rpm - 100]
    assert len(wrong) == 1, old  # sorted ranks: "1st rotational" meets 2x near 2480 rpm (16 el.: 2458)
    x = wrong[0]
    assert 2300 < x["rpm"] < 2700
    here = [c for c in res.crossings if c["order"] == 2.0 and abs(c["rpm"] - x["rpm"]) < 1.0]
    assert len(here) == 2 and all(c["label"].startswith("4th transverse") for c in here), here
    assert {c["curve_label"] for c in here} == {c["label"] for c in here}
    rot_cross = [c for c in res.crossings if c["order"] == 2.0 and c["label"].startswith("1st rotational")]
    assert len(rot_cross) == 1 and abs(rot_cross[0]["rpm"] - true_rot_rpm) < 1.0
    # what the shapes say, by an independent modal analysis (complex eigen-solver) at that speed
    m = drive_modal.analyse_modes(sc, float(drive.belt_speed(sc, x["rpm"])))
    near = np.flatnonzero(np.abs(m.frequencies_hz - x["frequency_hz"]) < 0.05)
    assert len(near) == 2
    for j in near:
        assert "transverse" in m.labels[j]
        share = sum(v[j] for k, v in m.energy_shares.items() if k.endswith("transverse"))
        assert share > 0.95
    r = [j for j, lab in enumerate(m.labels) if lab.startswith("1st rotational")]
    assert len(r) == 1 and abs(m.frequencies_hz[r[0]] - f_rot[-1]) < 0.1


def test_bench_curves_labels_and_repeated_pairs(bench):
    _, res = bench
    F = res.frequencies_hz
    assert res.tracked and res.stable.all() and np.all(np.isfinite(F))
    assert res.label_changes == [] and res.uncertain() == []
    assert np.all(np.diff(F[0]) >= -1e-9)  # columns in ascending order at the lowest speed
    assert F.shape[1] >= 12 and len(res.labels) == F.shape[1]
    # every repeated pair (the two equal spans) is two curves, one per span, at equal frequencies
    trans = [j for j, lab in enumerate(res.labels) if "transverse" in lab]
    spans = {lab.split()[-1] for j, lab in enumerate(res.labels) if j in trans}
    assert spans == {"crank-alternator", "alternator-crank"}
    for order in ("1st", "2nd", "3rd", "4th"):
        pair = [j for j in trans if res.labels[j].startswith(order)]
        assert len(pair) == 2 and {res.labels[j].split()[-1] for j in pair} == spans
        np.testing.assert_allclose(F[:, pair[0]], F[:, pair[1]], rtol=1e-8)
    # each crossing lies on its order line and on its curve
    for c in res.crossings:
        assert abs(c["frequency_hz"] - c["order"] * c["rpm"] / 60) < 1e-9
        f = np.interp(c["rpm"], res.rpm, F[:, c["mode"] - 1])
        assert abs(f - c["frequency_hz"]) < 0.05
    data = res.to_json()
    assert "tracked mode" in data["frequencies_meaning"] and data["tracking"]["modes_computed_per_speed"] > 12


# --------------------------------------------------------------------------- the tensioner bench


@pytest.fixture(scope="module")
def tensioner():
    """The tensioner bench, 4 elements per span, with a softer spring (12.6 N m/rad: spans at about
    270 N instead of 470 N) so that transverse modes come down through the alternator's rotational
    mode (~104 Hz) below 3200 rpm: one veers with it (tensioner-alternator span, coupled through the
    idler), one crosses it (the upper span)."""
    sc = _mesh(load_scene(SCENES / "tensioner_bench_stage2.toml"), 4)
    sc = parameters.set_value(sc, "tensioner.spring_stiffness", 12.6)
    rpm = np.arange(0.0, 3201.0, 100.0)
    return sc, rpm, campbell.analyse_campbell(sc, rpm, n_modes=10)


def test_tensioner_bench_curves_are_continuous(tensioner):
    """Each step of a tracked curve is no larger than twice the largest change of any sorted
    frequency over that step (at a true crossing a mode moves by its own slope; a wrong match
    would jump by the spacing of two modes)."""
    _, rpm, res = tensioner
    F = res.frequencies_hz
    assert np.all(np.isfinite(F)) and F.shape[1] >= 10
    S = np.sort(F, axis=1)
    drift = np.max(np.abs(np.diff(S, axis=0)), axis=1)  # (steps,)
    jump = np.abs(np.diff(F, axis=0))  # (steps, curves)
    assert np.all(jump <= 2.0 * drift[:, None] + 1e-9), np.argwhere(jump > 2.0 * drift[:, None])
    assert np.any(np.diff(np.argsort(F, axis=1), axis=0))  # two curves cross in this range
    assert res.uncertain() == []  # every step resolved (MAC >= 0.8 with the previous speed)


def test_tensioner_bench_veering_is_reported(tensioner):
    """The rotational mode and the tensioner-alternator span's 2nd transverse mode veer: the step
    (100 rpm) resolves the exchange, so each curve follows its branch and its label changes; both
    changes are reported, at the same speed, each curve taking the other's kind."""
    _, rpm, res = tensioner
    ch = res.label_changes
    assert len(ch) == 2 and ch[0]["rpm"] == ch[1]["rpm"] and ch[0]["mode"] != ch[1]["mode"], ch
    keys = [(mode_tracking.label_key(c["from"]), mode_tracking.label_key(c["to"])) for c in ch]
    assert keys[0] == keys[1][::-1]
    assert {k[0] for k in keys[0]} == {"rotational", "transverse"}
    for c in ch:  # the change is where the labels along the curve change
        j = c["mode"] - 1
        k = int(np.flatnonzero(rpm == c["rpm"])[0])
        assert res.labels_along[k - 1][j] == c["from"] and res.labels_along[k][j] == c["to"]
    # the other curves keep their kind and member all along
    for j in set(range(res.frequencies_hz.shape[1])) - {c["mode"] - 1 for c in ch}:
        assert len({mode_tracking.label_key(row[j]) for row in res.labels_along}) == 1
