"""Setting the belt and the static (steady-motion) equilibrium of a drive.

Installation (:func:`install`)
------------------------------
At installation, with the drive at rest and unloaded, the belt carries one
uniform tension ``T`` at stretch ``lam`` (``EA (lam^2 - 1)/2 * lam = T``) along
its whole path, and its unstretched length is ``path / lam``.

* two-pulley or fixed-centre drive: given ``static_tension`` the unstretched
  length follows; given ``length`` the stretch ``lam = path / length`` and the
  tension follow;
* tensioner drive: the arm angle balances the spring moment ``-k (theta -
  theta_0)`` against the belt's moment ``T (r x (t_out - t_in))`` on the idler.
  Given ``static_tension``, the arm angle solves that balance and the length
  follows; given ``length``, the tension depends on the arm angle through the
  path, ``lam(theta) = path(theta) / length``, and both are solved together.

The scalar arm balance is bracketed on a grid of arm angles (all of them, as
pure ``jax.numpy``, so that it runs under ``jit`` and ``vmap``), the stable root
(moment decreasing through zero) nearest the scene's ``arm_angle_deg`` (or the
spring's free angle) is refined by Newton, and derivatives come from the
implicit function theorem (``jax.lax.custom_root``).

Equilibrium (:func:`equilibrium`)
---------------------------------
Newton on the reduced residual ``F_ii(q_i, 0) = 0`` of :mod:`beltjax.drive`
from the installed straight-span state, with a backtracking line search and,
for hard cases, speed (load) stepping; implicit differentiation again through
``custom_root``, so the equilibrium is differentiable with respect to every
scene parameter.  At a belt speed the equilibrium is the steady motion (the
centrifugal terms of the moving belt included when ``transport`` is listed), and the belt's
compatibility, with ``belt_slip`` listed, is a running belt's: each arc holds the belt that ran
on there by classical creep theory (:func:`beltjax.friction.arc_belt_moved`), solved with the
equilibrium (``inst.creep``); a belt that grips (no ``belt_slip``) keeps its arcs as installed.
"""

from __future__ import annotations

import math
from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, drive, span
from beltjax.errors import BeltjaxError
from beltjax.drive import Installation, belt_slip, pivot
from beltjax.scene import TENSIONER, Scene

#: largest installation strain accepted (2 %, far beyond any belt's working strain): a
#: belt that would need more "cannot be fitted"; no static state may stretch a span further
MAX_INSTALL_STRAIN = 0.02
#: farthest a static state may turn the tensioner arm from its installed angle (rad, half a turn:
#: beyond any tensioner's travel; the mean loads have wound the arm round)
MAX_ARM_SWING = math.pi
#: the one retry policy of the statics: Newton from the installed state, and where it fails, again
#: with the speed (and its centrifugal and tensioner load) stepped from rest in RETRY_STEPS steps
#: (analyse_statics, solve_at, the sweeps); a batch over speeds (Campbell diagrams) steps every
#: speed from rest in SPEED_STEPS steps at once
RETRY_STEPS = 8
SPEED_STEPS = 4
#: arm angles scanned for the tensioner balance (rad, either side of the guess)
_ARM_GRID = 1440


class StaticsError(BeltjaxError):
    """A drive that has no admissible static state; one line naming the key or cause."""


# --------------------------------------------------------------------------- installation


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _arm_terms(theta, scene: Scene):
    """(path length m, belt moment per unit tension m, wrap on the idler rad) at arm angle theta."""
    g = scene.geometry(theta, check=False)
    k = scene.route.order.index(TENSIONER)
    t_out, t_in = g.span_tangent[k], g.span_tangent[k - 1]
    t = scene.tensioner
    r = t.idler_center(theta) - t.pivot
    return g.length, _cross(r, t_out - t_in), g.wrap[k]


def _arm_residual(theta, scene: Scene):
    """Moment balance on the arm (N m) at installation; its root is the installed arm angle."""
    path, arm, _ = _arm_terms(theta, scene)
    b, t = scene.belt, scene.tensioner
    if b.static_tension is not None:
        T = b.static_tension
    else:
        T = ancf.axial_force(path / b.length, b.EA)
    return T * arm + pivot.elastic_moment(theta, t)


def _arm_guess(scene: Scene):
    t = scene.tensioner
    return jnp.deg2rad(t.arm_angle_deg if t.arm_angle_deg is not None else t.spring_preload_deg)


def _arm_scan(scene: Scene):
    """Grid scan of the arm balance over the guess +- half a turn: the grid (rad), each cell's
    linearly interpolated root (rad) and whether the cell brackets a stable root."""
    th = _arm_guess(scene) + jnp.linspace(-jnp.pi, jnp.pi, _ARM_GRID + 1)
    r = jax.vmap(lambda x: _arm_residual(x, scene))(th)
    path, _, wrap = jax.vmap(lambda x: _arm_terms(x, scene))(th)
    ok = jnp.isfinite(r) & (wrap > 0) & (wrap < jnp.pi)
    if scene.belt.length is not None:
        ok = ok & (path > scene.belt.length)
    down = ok[:-1] & ok[1:] & (r[:-1] > 0) & (r[1:] <= 0)
    # linear interpolation inside each bracketing cell
    x = th[:-1] + r[:-1] / jnp.where(down, r[:-1] - r[1:], 1.0) * (th[1:] - th[:-1])
    return th, x, down


def _bracket_arm(scene: Scene):
    """Grid scan for the stable root of the arm balance nearest the guess (rad; nan if none)."""
    th, x, down = _arm_scan(scene)
    dist = jnp.where(down, jnp.abs(x - _arm_guess(scene)), jnp.inf)
    j = jnp.argmin(dist)
    return jnp.where(jnp.isfinite(dist[j]), x[j], jnp.nan), th[j], th[j + 1]


def arm_balances(scene: Scene):
    """Every stable balance of the tensioner arm against the installed belt within half a turn of
    the guess (rad, to the scan's linear interpolation; NaN in the other cells, shape
    (_ARM_GRID,)): :func:`install` takes the one nearest the guess (``tensioner.arm_angle_deg``,
    else ``spring_preload_deg``)."""
    _, x, down = _arm_scan(scene)
    return jnp.where(down, x, jnp.nan)


def _solve_arm(scene: Scene):
    def f(theta):
        return _arm_residual(theta, scene)

    def solve(f, x0):
        x0, lo, hi = jax.lax.stop_gradient(_bracket_arm(scene))

        def body(_, x):
            step = f(x) / jax.grad(f)(x)
            return jnp.clip(x - step, lo, hi)  # the root lies in the bracketing cell

        return jax.lax.fori_loop(0, 30, body, x0)

    return jax.lax.custom_root(f, _arm_guess(scene), solve, lambda g, y: y / g(1.0))


def install(scene: Scene) -> Installation:
    """The installed belt: arm angle, stretch, tension, unstretched length and path.

    Pure and differentiable with respect to every scene parameter; use
    :func:`check_installation` on concrete results for one-line errors.
    """
    b = scene.belt
    if scene.tensioner is not None:
        theta = _solve_arm(scene)
    else:
        theta = jnp.zeros(())
    centers, radii = scene.layout(theta)
    g = scene.geometry(theta, check=False)
    if b.static_tension is not None:
        T = jnp.asarray(b.static_tension)
        lam = span.stretch_for_tension(T, b.EA)
        L = g.length / lam
    else:
        L = jnp.asarray(b.length)
        lam = g.length / L
        T = ancf.axial_force(lam, b.EA)
    return Installation(
        arm_angle=theta, stretch=lam, tension=T, belt_length=L, centers=centers, radii=radii,
        span_start=g.span_start, span_end=g.span_end, span_tangent=g.span_tangent,
        span_length=g.span_length, wrap=g.wrap, creep=jnp.zeros_like(g.span_length),
    )


def check_solved(scene: Scene, tension_N: float, arm_angle_deg: float | None = None) -> None:
    """Raise :class:`StaticsError` (one line) if the solved installation fails a check that the
    scene alone could not decide (:func:`beltjax.validate.solved_status`): a tensioner's idler
    that overlaps a pulley, or leaves no belt path, at its equilibrium arm angle ``arm_angle_deg``
    (deg; key ``tensioner``), or an axial stiffness that swamps the string stiffness at the
    installation tension ``tension_N`` (N; key ``belt.EA``)."""
    from beltjax import validate

    status, first = validate.solved_status(scene, tension_N, arm_angle_deg)
    st = str(status[0])
    if st == "ok":
        return
    msg = first[st][1]
    if st in ("overlap", "no_belt_path"):
        raise StaticsError(f"at its equilibrium arm angle {arm_angle_deg:.4g} deg: {msg.split(': ', 1)[1]}", "tensioner")
    raise StaticsError(msg)


def installation_faults(scene: Scene, inst: Installation) -> dict:
    """Whether the belt cannot be installed, by cause (JAX bools; pure, vmappable): the one
    installability test of statics, sweeps and optimisation.  no_arm_balance: no tensioner arm
    angle balances the spring; belt_slack: the unstretched belt is not shorter than its path;
    belt_overstretched: it stretches more than MAX_INSTALL_STRAIN to go round."""
    lam = inst.stretch
    return dict(no_arm_balance=jnp.asarray(scene.tensioner is not None) & ~jnp.isfinite(inst.arm_angle),
                belt_slack=~jnp.isfinite(lam) | (lam <= 1.0),
                belt_overstretched=lam - 1.0 > MAX_INSTALL_STRAIN)


def operating_faults(scene: Scene, qi, inst: Installation) -> dict:
    """Whether the static state ``qi`` (rad; a solved equilibrium) is past what any belt drive
    carries, by cause (JAX bools; pure, vmappable): the one such test of statics, sweeps, responses
    over speed and optimisation.  span_overstretched: a span stretched more than
    MAX_INSTALL_STRAIN of its unstretched length; arm_wound: the tensioner arm turned more than
    MAX_ARM_SWING from its installed angle.  Either means the mean loads overpower the belt (a
    solution of the equations, not of a drive)."""
    _, theta = drive.angles_and_arm(qi, scene, inst)
    return dict(span_overstretched=jnp.max(operating_strains(scene, qi, inst)) > MAX_INSTALL_STRAIN,
                arm_wound=jnp.asarray(scene.tensioner is not None) & (jnp.abs(theta - inst.arm_angle) > MAX_ARM_SWING))


def operating_strains(scene: Scene, qi, inst: Installation):
    """Each span's strain (n,) (-) at the state ``qi`` (rad): its belt length over its unstretched
    length, less 1 (as :func:`beltjax.drive.element_length`)."""
    return drive.span_lengths(qi, scene, inst) / (inst.span_length / inst.stretch) - 1.0


def check_installation(scene: Scene, inst: Installation) -> None:
    """Raise :class:`StaticsError` (one line, naming the cause of :func:`installation_faults`)
    if the belt cannot be installed as given."""
    b = scene.belt
    key = "belt.length" if b.length is not None else "belt.static_tension"
    faults = {k: bool(v) for k, v in installation_faults(scene, inst).items()}
    if faults["no_arm_balance"]:
        th = _arm_guess(scene) + jnp.linspace(-jnp.pi, jnp.pi, _ARM_GRID + 1)
        path, _, wrap = jax.vmap(lambda x: _arm_terms(x, scene))(th)
        r = jax.vmap(lambda x: _arm_residual(x, scene))(th)
        ok = np.asarray(jnp.isfinite(r) & (wrap > 0) & (wrap < jnp.pi))
        if b.length is not None and not np.any(ok & (np.asarray(path) > float(b.length))):
            raise StaticsError(
                f"belt too long to fit: {float(b.length):.6g} m is longer than the belt path at every "
                f"tensioner arm angle (longest {float(np.max(np.where(ok, path, 0))):.6g} m); it would hang slack",
                key,
            )
        t = scene.tensioner
        if b.length is not None:
            path0 = float(_arm_terms(jnp.deg2rad(t.spring_preload_deg), scene)[0])
            if path0 <= float(b.length):  # the arm rests at the spring's free angle, the belt slack
                raise StaticsError(
                    f"belt too long to fit: no arm angle where the belt is taut balances the spring, and at "
                    f"the spring's free angle ({float(t.spring_preload_deg):.4g} deg) the belt path "
                    f"{path0:.6g} m is shorter than the belt ({float(b.length):.6g} m); it would hang slack",
                    key,
                )
        raise StaticsError(
            "no tensioner arm angle balances the spring against the belt (belt too short, or the "
            "spring too weak, for this layout); check the belt, spring_preload_deg and spring_stiffness",
            key,
        )
    lam = float(inst.stretch)
    if faults["belt_slack"]:
        raise StaticsError(
            f"belt too long to fit: the unstretched length {float(inst.belt_length):.6g} m is not shorter "
            f"than the belt path {float(inst.belt_length * inst.stretch):.6g} m, so the belt would hang slack",
            key,
        )
    if faults["belt_overstretched"]:
        raise StaticsError(
            f"belt too short to fit: it would have to stretch {100 * (lam - 1):.3g} % (tension "
            f"{float(inst.tension):.4g} N) to reach round the pulleys (limit {100 * MAX_INSTALL_STRAIN:.3g} %)",
            key,
        )
    t = scene.tensioner
    if t is not None:  # the end stops must contain the installed arm (else it rests on a stop)
        a = math.degrees(float(inst.arm_angle))
        if on := pivot.stop_pressed(t, a):
            raise StaticsError(
                f"the arm settles at {a:.4g} deg, on its stop at {on[1]:.4g} deg: the stops must contain "
                "the installed arm angle (move the stop, or check the spring and the belt)", f"tensioner.{on[0]}")


# --------------------------------------------------------------------------- equilibrium


def _newton(f, q0, max_iter: int = 40, xtol: float = 1e-11):
    """Newton with a backtracking line search; returns (q, (converged, iterations, |f|)) (floats).

    The line search uses the natural monotonicity test (Deuflhard): a step length a is
    accepted when the simplified Newton correction at q + a d, computed with the same
    factorised Jacobian, shrinks, |K^-1 f(q + a d)| <= (1 - a/4) |d|.  Unlike a test on
    |f|, it does not depend on the units of the residual (forces and moments mixed).
    """
    if q0.size == 0:  # nothing to solve (every pulley driven, the spans bars): the installed state
        return q0, (jnp.ones((), q0.dtype), jnp.zeros((), q0.dtype), jnp.zeros((), q0.dtype))
    alphas = 0.5 ** jnp.arange(8.0)

    def cond(state):
        _, it, done, _ = state
        return (~done) & (it < max_iter)

    def body(state):
        q, it, _, _ = state
        R = f(q)
        lu = jax.scipy.linalg.lu_factor(jax.jacfwd(f)(q))
        d = -jax.scipy.linalg.lu_solve(lu, R)
        nd = jnp.linalg.norm(d)

        def untried(s):
            j, good, _, _, _ = s
            return ~good & (j < alphas.size)

        def trial(s):  # the first step length that passes, else the one of least finite correction
            j, _, k, best, rk = s
            Rt = f(q + alphas[j] * d)
            nbar, nres = jnp.linalg.norm(jax.scipy.linalg.lu_solve(lu, Rt)), jnp.linalg.norm(Rt)
            good = jnp.isfinite(nbar) & (nbar <= (1.0 - alphas[j] / 4) * nd)
            take = good | (jnp.isfinite(nbar) & (nbar < best)) | (j == 0)
            return (j + 1, good, jnp.where(take, j, k), jnp.where(take & jnp.isfinite(nbar), nbar, best),
                    jnp.where(take, nres, rk))

        # one trial at a time (the full step passes in most iterations): measured on the tensioner
        # bench, the equilibrium's XLA compilation fell from 7.4 s to 5.8 s against all eight at once
        _, _, k, _, rk = jax.lax.while_loop(untried, trial, (0, False, 0, jnp.inf, jnp.inf))
        step = alphas[k] * d
        q = q + step
        small = jnp.max(jnp.abs(step)) < xtol * (1.0 + jnp.max(jnp.abs(q)))
        return q, it + 1, small | ~jnp.all(jnp.isfinite(step)), rk

    q, it, done, rn = jax.lax.while_loop(cond, body, (q0, 0, False, jnp.inf))
    conv = done & jnp.all(jnp.isfinite(q))
    # diagnostics as floats: custom_root's derivative rule needs float auxiliaries
    return q, (conv.astype(q.dtype), jnp.asarray(it, q.dtype), rn)


@eqx.filter_jit
def _static_residual(qi, scene: Scene, inst: Installation, speed, loaded):
    """:func:`beltjax.drive.static_residual`, jitted on its own so that Newton's several calls of
    it (residual, Jacobian, line search, the implicit derivative) trace the drive's equations once
    per compilation and reuse the traced program (XLA inlines it; the compiled statics is the
    same): measured on the eight-pulley hybrid drive, the statics' tracing fell by 15-35 %
    (three interleaved pairs, 2026-11-27, an ad hoc measurement: benchmarks/README §5i)."""
    return drive.static_residual(qi, scene, inst, speed, loaded)


@eqx.filter_jit
def _running_creep(qi, scene: Scene, inst: Installation, speed):
    """The belt each arc hands its exit span in the steady motion at belt speed ``speed`` (m/s)
    about q_i (m, :func:`beltjax.friction.arc_belt_moved` of the spans' forces and stretches);
    zero at rest, where the belt has not run over the arcs since it was installed."""
    from beltjax import critical, friction  # critical imports this module

    tensions, lam = critical.span_state(scene, qi, inst)  # the spans' forces as the equations see them
    c = drive.effects_of(scene).transport_speed(drive.transport_speed(scene, inst, speed))
    forces = critical.pulley_forces(tensions, lam, c, scene.belt.rhoA)
    moved = friction.arc_belt_moved(forces, lam, drive.wraps(qi, scene, inst), inst.radii, inst.stretch,
                                    friction.effective_coefficients(scene))
    return jnp.where(jnp.abs(speed) > 0, moved, 0.0)


def equilibrium(scene: Scene, inst: Installation | None = None, speed=None, steps: int = 1, loaded: bool = False):
    """Static (steady-motion) equilibrium: independent coordinates and diagnostics.

    speed: belt speed (m/s; default from the drive pulley's speed_rpm);
    steps: speed (load) steps from rest to ``speed`` (the mean loads stepped with it);
    loaded: the operating point (the scene's mean loads act: :func:`beltjax.drive.mean_body_loads`)
    rather than the unloaded state.  With ``belt_slip`` listed (a belt that creeps) a running
    belt (speed != 0) is solved with its compatibility: the belt on each arc is the belt that ran
    on there, at its arriving span's stretch and over the sliding arc at the exit going to its
    exit span's (:func:`beltjax.friction.arc_belt_moved`), so each arc hands its exit span the
    belt it no longer holds (``inst.creep``, m, solved together with q_i); at rest, or without
    ``belt_slip`` (the belt grips every rim and cannot creep), the arcs keep the belt as ``inst``
    has it (as installed).  Returns ``(qi, inst, (converged, iterations, residual_norm))``, inst
    with its ``creep`` (floats; converged is 1.0 or 0.0); differentiable in every scene parameter
    by the implicit function theorem.
    """
    inst = install(scene) if inst is None else inst
    speed = drive.belt_speed(scene) if speed is None else speed
    full0 = drive.installed_coordinates(scene, inst)
    dofs = drive.static_dofs(scene)
    k = len(dofs)
    running = belt_slip.running(scene)  # a belt that creeps (else it grips: arcs kept)
    z0 = jnp.concatenate([full0[dofs], inst.creep]) if running else full0[dofs]

    def unpack(z):
        return full0.at[dofs].set(z[:k]), inst._replace(creep=z[k:]) if running else inst

    def residual(z, v):
        qi, at = unpack(z)
        forces = _static_residual(qi, scene, at, v, loaded)[dofs]
        if not running:
            return forces
        return jnp.concatenate([forces, z[k:] - _running_creep(qi, scene, at, v)])

    def f(z):
        return residual(z, speed)

    def solve(f, z_init):
        if steps == 1:
            return _newton(f, z_init)

        def stage(z, frac):
            g = lambda x: residual(x, speed * frac)  # noqa: E731
            z, info = _newton(g, z)
            return z, info

        z, infos = jax.lax.scan(stage, z_init, jnp.arange(1, steps + 1) / steps)
        return z, jax.tree.map(lambda a: a[-1], infos)

    def tangent_solve(g, y):
        return jnp.linalg.solve(jax.jacfwd(g)(y), y)

    z, info = jax.lax.custom_root(f, z0, solve, tangent_solve, has_aux=True)
    qi, at = unpack(z)
    return qi, at, info


# --------------------------------------------------------------------------- compiled statics


install_compiled = jax.jit(install)
"""The jitted :func:`install` (lengths m, tension N, arm angle rad), compiled once per scene structure."""


@partial(jax.jit, static_argnames=("steps",))
def _statics_core(scene: Scene, speed, loaded, steps: int = 1):
    # loaded: a traced weight (1.0 or 0.0) on the mean loads, so that the operating point and the
    # unloaded state of one drive share this compilation
    qi, inst, info = equilibrium(scene, speed=speed, steps=steps, loaded=loaded)
    return static_outputs(scene, qi, inst, speed, loaded), info


def static_outputs(scene, qi, inst, speed, loaded: bool = False):
    """Outputs at equilibrium ``qi``, belt speed ``speed`` (m/s): q, theta (rad), tensions, hubs (N),
    lengths (m; the model's, between its end nodes), free_lengths (m; tangent to tangent,
    :func:`beltjax.drive.free_lengths`), end_slides (m, (n, 2): :func:`beltjax.drive.end_slides`),
    strains (-, :func:`operating_strains`), faults
    (:func:`operating_faults`), wraps (rad, of the solved layout: an arm's swing turns them,
    :func:`beltjax.drive.wraps`), the drive pulley's torque (N m), the mean loads on the bodies
    (N m) and with a tensioner arm_balances (rad, :func:`arm_balances`)."""
    q = drive.full_coordinates(qi, scene, inst)
    _, theta = drive.angles_and_arm(qi, scene, inst)
    return dict(
        qi=qi, q=q, inst=inst, theta=theta,
        tensions=drive.span_tensions(q, scene, inst),
        hubs=drive.hub_forces(q, scene, inst, speed),
        lengths=drive.full_span_lengths(q, scene),
        wraps=drive.wraps(qi, scene, inst), free_lengths=drive.free_lengths(qi, scene, inst),
        end_slides=drive.end_slides(qi, scene, inst),
        **({} if scene.tensioner is None else {"arm_balances": arm_balances(scene)}),
        strains=operating_strains(scene, qi, inst), faults=operating_faults(scene, qi, inst),
        drive_torque=drive.drive_torque(qi, scene, inst, speed, loaded),
        loads=(loaded * drive.mean_body_loads(scene, inst, speed)[:, 2] if loaded is not False
               else jnp.zeros(len(drive.body_names(scene)))),
    )


def solve_at(scene: Scene, v: float, loaded: bool = False, check=None):
    """(:func:`static_outputs` at belt speed v (m/s), converged (bool), Newton iterations,
    residual norm) of the (canonical) scene, at its operating point with ``loaded`` (else
    unloaded); speed stepping when Newton from the installed state fails
    (:data:`RETRY_STEPS`).  Compiled once per scene structure (v is traced).  check: called
    with the installation the first solve started from (e.g. :func:`check_installation`),
    before any retry: the installation comes out of the same compiled program."""
    w = jnp.asarray(1.0 if loaded else 0.0)
    out, (conv, it, rn) = _statics_core(scene, v, w)
    if check is not None:
        check(out["inst"])
    if not float(conv) > 0.5:
        out, (conv, it, rn) = _statics_core(scene, v, w, steps=RETRY_STEPS)
    return out, float(conv) > 0.5, int(it), float(rn)


from beltjax.static_state import StaticResult, analyse_statics, _state  # noqa: E402,F401  (moved there; it imports this module)
