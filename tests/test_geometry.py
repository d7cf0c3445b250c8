"""Drive geometry: closed-form belt lengths, wrap angles, tangency, gradients, checks."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from beltjax import geometry as g

# (D, R1, R2, direction of the centre line in rad): R1 > R2, R1 < R2, equal radii
TWO_PULLEY_CASES = [
    (0.6766, 0.1015, 0.0375, 3.2374),  # the thesis' bench at T = 600 N, roughly
    (0.5, 0.03, 0.12, 0.7),
    (0.3, 0.08, 0.08, -2.1),
    (0.25, 0.11, 0.02, 1.4),
]


def _two_pulleys(D, R1, R2, phi, back_side=()):
    c1 = np.array([0.3, -0.1])
    c2 = c1 + D * np.array([math.cos(phi), math.sin(phi)])
    senses = g.wrap_senses(["a", "b"], back_side)
    return np.stack([c1, c2]), np.array([R1, R2]), senses


def _open_closed_form(D, R1, R2):
    return 2 * math.sqrt(D**2 - (R1 - R2) ** 2) + math.pi * (R1 + R2) + 2 * (R1 - R2) * math.asin((R1 - R2) / D)


def _crossed_closed_form(D, R1, R2):
    return 2 * math.sqrt(D**2 - (R1 + R2) ** 2) + (R1 + R2) * (math.pi + 2 * math.asin((R1 + R2) / D))


def _thesis_bench(theta):
    """Crank, tensioner idler (arm angle theta, rad), alternator of the thesis' tensioner bench."""
    idler = g.tensioner_idler_center(jnp.array([0.64335, 0.0884]), 0.094, theta)
    centers = jnp.stack([jnp.array([0.8973, 0.2]), idler, jnp.array([0.2425, 0.135])])
    radii = jnp.array([0.1015, 0.037, 0.0375])
    return centers, radii, g.wrap_senses(["crank", "tensioner", "alternator"], ["tensioner"])


# --------------------------------------------------------------------------- senses


def test_wrap_senses():
    assert g.wrap_senses(["a", "b", "c"]).tolist() == [-1, -1, -1]
    assert g.wrap_senses(["a", "b", "c"], ["b"]).tolist() == [-1, 1, -1]
    assert g.wrap_senses(["a", "b", "c"], ["b"], "ccw").tolist() == [1, -1, 1]
    with pytest.raises(ValueError, match="direction"):
        g.wrap_senses(["a", "b"], direction="left")
    with pytest.raises(ValueError, match="'z'"):
        g.wrap_senses(["a", "b"], ["z"])


# --------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("D,R1,R2,phi", TWO_PULLEY_CASES)
def test_open_belt_length_closed_form(D, R1, R2, phi):
    c, R, s = _two_pulleys(D, R1, R2, phi)
    geo = g.drive_geometry(c, R, s)
    assert abs(float(geo.length) - _open_closed_form(D, R1, R2)) < 1e-12
    assert abs(float(g.two_pulley_length(D, R1, R2)) - _open_closed_form(D, R1, R2)) < 1e-12
    # both spans have the tangent length, wraps pi +- 2 asin((R1 - R2)/D) and sum to 2 pi
    np.testing.assert_allclose(geo.span_length, math.sqrt(D**2 - (R1 - R2) ** 2), rtol=0, atol=1e-13)
    beta = math.asin((R1 - R2) / D)
    np.testing.assert_allclose(geo.wrap, [math.pi + 2 * beta, math.pi - 2 * beta], rtol=0, atol=1e-12)
    assert abs(float(jnp.sum(geo.wrap)) - 2 * math.pi) < 1e-12
    np.testing.assert_allclose(geo.arc_length, R * np.asarray(geo.wrap), rtol=1e-14)


@pytest.mark.parametrize("D,R1,R2,phi", TWO_PULLEY_CASES)
def test_crossed_belt_length_closed_form(D, R1, R2, phi):
    c, R, s = _two_pulleys(D, R1, R2, phi, back_side=["b"])
    geo = g.drive_geometry(c, R, s)
    assert abs(float(geo.length) - _crossed_closed_form(D, R1, R2)) < 1e-12
    assert abs(float(g.two_pulley_length(D, R1, R2, crossed=True)) - _crossed_closed_form(D, R1, R2)) < 1e-12
    wrap = math.pi + 2 * math.asin((R1 + R2) / D)
    np.testing.assert_allclose(geo.wrap, [wrap, wrap], rtol=0, atol=1e-12)
    # a figure-of-eight: the signed turning adds to zero
    assert abs(float(jnp.sum(jnp.asarray(s) * geo.wrap))) < 1e-12


def test_tangent_line_single_pair_matches_drive():
    c, R, s = _two_pulleys(0.5, 0.03, 0.12, 0.7)
    tl = g.tangent_line(c[0], R[0], s[0], c[1], R[1], s[1])
    geo = g.drive_geometry(c, R, s)
    np.testing.assert_allclose(tl.start, geo.span_start[0], atol=1e-15)
    np.testing.assert_allclose(tl.end, geo.span_end[0], atol=1e-15)
    assert abs(float(tl.length - geo.span_length[0])) < 1e-15


# --------------------------------------------------------------------------- tangency, wraps


def _serpentine():
    """A five-pulley serpentine drive with one back-side idler (m)."""
    names = ["crank", "ac", "alt", "ps", "idler"]
    centers = np.array([[0.0, 0.0], [-0.18, 0.02], [-0.15, 0.25], [0.05, 0.30], [0.10, 0.14]])
    radii = np.array([0.08, 0.055, 0.03, 0.06, 0.03])
    return names, centers, radii, g.wrap_senses(names, ["idler"])


@pytest.mark.parametrize("layout", ["open", "crossed", "serpentine", "thesis"])
def test_tangent_points_on_circles_and_perpendicular(layout):
    if layout == "open":
        c, R, s = _two_pulleys(0.5, 0.03, 0.12, 0.7)
    elif layout == "crossed":
        c, R, s = _two_pulleys(0.5, 0.03, 0.12, 0.7, ["a"])
    elif layout == "serpentine":
        _, c, R, s = _serpentine()
    else:
        c, R, s = _thesis_bench(math.radians(46.5))
    geo = g.drive_geometry(c, R, s)
    c = np.asarray(c)
    n = len(R)
    nxt = (np.arange(n) + 1) % n
    for pts, idx in ((geo.span_start, np.arange(n)), (geo.span_end, nxt)):
        radial = np.asarray(pts) - c[idx]
        np.testing.assert_allclose(np.linalg.norm(radial, axis=1), np.asarray(R)[idx], rtol=0, atol=1e-14)
        # span perpendicular to the radius at the tangent point
        np.testing.assert_allclose(np.sum(radial * np.asarray(geo.span_tangent), axis=1), 0.0, atol=1e-14)
    chord = np.asarray(geo.span_end - geo.span_start)
    np.testing.assert_allclose(chord, np.asarray(geo.span_length)[:, None] * np.asarray(geo.span_tangent), atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(geo.span_tangent, axis=1), 1.0, atol=1e-15)
    # the travel direction at the departure point, s * perp(radial), is the span tangent
    radial = np.asarray(geo.span_start) - c
    travel = np.asarray(s)[:, None] * np.stack([-radial[:, 1], radial[:, 0]], axis=1) / np.asarray(R)[:, None]
    np.testing.assert_allclose(travel, geo.span_tangent, atol=1e-14)
    # contact angles agree with the points
    np.testing.assert_allclose(np.cos(geo.depart_angle) * np.asarray(R) + c[:, 0], geo.span_start[:, 0], atol=1e-14)
    arrive = np.roll(np.asarray(geo.span_end), 1, axis=0)
    np.testing.assert_allclose(np.sin(geo.arrive_angle) * np.asarray(R) + c[:, 1], arrive[:, 1], atol=1e-14)


def test_wrap_angles_are_the_contact_arcs():
    """Each wrap is the angle from arrival to departure point, in the pulley's sense."""
    names, c, R, s = _serpentine()
    geo = g.drive_geometry(c, R, s, names=names)
    arc = np.mod(s * (np.asarray(geo.depart_angle) - np.asarray(geo.arrive_angle)), 2 * np.pi)
    np.testing.assert_allclose(geo.wrap, arc, atol=1e-12)
    assert np.all((np.asarray(geo.wrap) > 0) & (np.asarray(geo.wrap) < 2 * np.pi))
    # a simple loop run clockwise turns once clockwise
    assert abs(float(jnp.sum(jnp.asarray(s) * geo.wrap)) + 2 * np.pi) < 1e-12
    total = float(jnp.sum(geo.span_length) + jnp.sum(geo.arc_length))
    assert abs(float(geo.length) - total) < 1e-15


def test_reversed_route_ccw_is_the_same_belt():
    names, c, R, s = _serpentine()
    fwd = g.drive_geometry(c, R, s)
    rs = g.wrap_senses(names[::-1], ["idler"], "ccw")
    rev = g.drive_geometry(c[::-1], R[::-1], rs)
    assert abs(float(fwd.length - rev.length)) < 1e-14
    np.testing.assert_allclose(np.sort(fwd.wrap), np.sort(rev.wrap), atol=1e-13)
    np.testing.assert_allclose(np.sort(fwd.span_length), np.sort(rev.span_length), atol=1e-14)


def test_thesis_tensioner_bench_idler_on_lower_strand_back_side():
    """Route crank -> tensioner -> alternator (cw, idler on the back) at the thesis' arm angles."""
    for deg in (44.3, 46.5, 46.8):
        c, R, s = _thesis_bench(math.radians(deg))
        geo = g.drive_geometry(c, R, s, names=["crank", "tensioner", "alternator"])
        wrap = np.degrees(np.asarray(geo.wrap))
        assert 200 < wrap[0] < 240 and 30 < wrap[1] < 60 and 170 < wrap[2] < 190
        # the belt touches the idler on its upper half (belt above the idler centre), i.e.
        # the idler pushes the lower strand up into the loop
        for a in (geo.arrive_angle[1], geo.depart_angle[1]):
            assert 0 < float(a) < math.pi
        # the idler's contact points lie below the upper strand alternator -> crank
        a, t = np.asarray(geo.span_start[2]), np.asarray(geo.span_tangent[2])
        for p in (np.asarray(geo.span_end[0]), np.asarray(geo.span_start[1])):
            upper_y = a[1] + (p[0] - a[0]) * t[1] / t[0]
            assert p[1] < upper_y - 0.05
        assert abs(float(jnp.sum(jnp.asarray(s) * geo.wrap)) + 2 * np.pi) < 1e-12


def test_idler_center():
    p = g.tensioner_idler_center(jnp.array([1.0, 2.0]), 0.5, jnp.pi / 2)
    np.testing.assert_allclose(p, [1.0, 2.5], atol=1e-15)
    p = g.tensioner_idler_center(jnp.array([0.0, 0.0]), 2.0, math.radians(150))
    np.testing.assert_allclose(p, [2 * math.cos(math.radians(150)), 1.0], atol=1e-15)


# --------------------------------------------------------------------------- gradients


def _fd(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_grad_length_wrt_centre_matches_finite_difference():
    c, R, s = _thesis_bench(math.radians(46.5))
    c = np.asarray(c)
    R = np.asarray(R)

    def length_x(x):  # alternator centre x
        cc = jnp.asarray(c).at[2, 0].set(x)
        return g.drive_geometry(cc, R, s).length

    x0 = float(c[2, 0])
    gr = float(jax.grad(length_x)(x0))
    fd = float(_fd(length_x, x0, 1e-5))
    assert abs(gr - fd) < 1e-9 * max(1.0, abs(gr))
    # open two-pulley drive: dL/dD from the closed form is 2 cos(beta)
    D, R1, R2, phi = TWO_PULLEY_CASES[1]

    def length_D(d):
        cc = jnp.stack([jnp.zeros(2), d * jnp.array([math.cos(phi), math.sin(phi)])])
        return g.belt_length(cc, jnp.array([R1, R2]), g.wrap_senses(["a", "b"]))

    beta = math.asin((R1 - R2) / D)
    assert abs(float(jax.grad(length_D)(D)) - 2 * math.cos(beta)) < 1e-12


def test_grad_wrt_radii_and_arm_angle_matches_finite_difference():
    def f(theta, radii):
        c, _, s = _thesis_bench(theta)
        geo = g.drive_geometry(c, radii, s)
        return geo.length + 0.1 * geo.wrap[1] + 0.3 * geo.span_length[0]

    th0 = math.radians(46.5)
    R0 = jnp.array([0.1015, 0.037, 0.0375])
    gth, gR = jax.jit(jax.grad(f, argnums=(0, 1)))(th0, R0)
    assert abs(float(gth) - float(_fd(lambda t: f(t, R0), th0, 1e-6))) < 1e-8
    for k in range(3):
        e = jnp.zeros(3).at[k].set(1.0)
        fd = float(_fd(lambda h: f(th0, R0 + h * e), 0.0, 1e-6))
        assert abs(float(gR[k]) - fd) < 1e-8


def test_jit_and_vmap_over_arm_angle():
    def length(theta):
        c, R, s = _thesis_bench(theta)
        return g.drive_geometry(c, R, s).length

    thetas = jnp.deg2rad(jnp.array([44.3, 46.5, 46.8]))
    L = jax.jit(jax.vmap(length))(thetas)
    assert np.all(np.diff(np.asarray(L)) > 0)  # opening the arm stretches the belt
    assert abs(float(L[0]) - float(length(thetas[0]))) < 1e-15


# --------------------------------------------------------------------------- checks

BAD_LAYOUTS = [
    # (centres, radii, names, back_side, message fragment)
    ([[0, 0], [0.05, 0]], [0.3, 0.1], ["A", "B"], [], "no open tangent from 'A' to 'B'"),
    ([[0, 0], [0.35, 0]], [0.3, 0.1], ["A", "B"], ["B"], "no crossed tangent from 'A' to 'B'"),
    ([[0, 0], [0.35, 0]], [0.3, 0.1], ["A", "B"], [], "pulleys 'A' and 'B' overlap"),
    ([[0, 0], [1, 0], [0.1, 0.05]], [0.1, 0.1, 0.05], ["A", "B", "C"], [], "pulleys 'A' and 'C' overlap"),
    ([[0, 0], [0.5, 0.0], [1, 0]], [0.1, 0.1, 0.1], ["A", "C", "B"], [], "wrap angle on pulley 'C' degenerates"),
    ([[0, 0], [1, 0], [0.5, 0.1]], [0.1, 0.1, 0.05], ["A", "B", "C"], [], "passes through pulley 'C'"),
    ([[0, 0], [1, 0], [0.5, 0.3]], [0.1, 0.1, 0.05], ["A", "B", "C"], [], "cross each other"),
    ([[0, 0], [1, 0]], [0.1, -0.1], ["A", "B"], [], "pulley 'B': radius must be > 0"),
]


@pytest.mark.parametrize("centers,radii,names,back,fragment", BAD_LAYOUTS)
def test_bad_layouts_raise_one_line_errors(centers, radii, names, back, fragment):
    s = g.wrap_senses(names, back)
    with pytest.raises(ValueError) as info:
        g.drive_geometry(np.array(centers, float), np.array(radii, float), s, names=names)
    assert isinstance(info.value, g.GeometryError)
    msg = str(info.value)
    assert fragment in msg and "\n" not in msg


def test_thesis_idler_wrapped_by_inner_side_is_rejected():
    """The same idler wrapped by the belt's inner side would loop round it: spans cross."""
    c, R, _ = _thesis_bench(math.radians(46.5))
    s = g.wrap_senses(["crank", "tensioner", "alternator"])
    with pytest.raises(g.GeometryError, match="'crank' -> 'tensioner' and 'tensioner' -> 'alternator' cross"):
        g.drive_geometry(c, R, s, names=["crank", "tensioner", "alternator"])


def test_checks_skipped_under_tracing():
    # inside jit the values are unknown: no exception, the numbers say NaN
    s = g.wrap_senses(["A", "B"])
    out = jax.jit(lambda c: g.drive_geometry(c, jnp.array([0.3, 0.1]), s).length)(jnp.array([[0.0, 0], [0.05, 0]]))
    assert np.isnan(float(out))
