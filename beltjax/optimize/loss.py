"""The pure-JAX loss: measures of a layout, the resonance and constraint terms, the compiled value and gradient."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import critical, drive, drive_modal, friction, parameters, statics
from beltjax.scene import Scene
from beltjax.drive import couplings
from beltjax.optimize import modes
from beltjax.optimize.problem import _UNIT, SOFT_HZ, Constraint, Problem, _band_starts, _bands, _pairs, sample_rpm
from beltjax.drive.effects import effects_of


#: weight at which a mode is watched in the exact max (the goal and the reports): 1, the
#: selection's full weight (a span mode by its label); the smooth loss also counts smaller weights
WATCHED = 1.0


def _watches_span(problem: Problem) -> bool:
    return any(o.modes == "span" for o in _bands(problem))


def measures(scene: Scene, problem: Problem, x, rpm=None) -> dict:
    """Every quantity the objectives and constraints use, at parameter values ``x`` (pure JAX).

    x: (n_variables,) values in file units; rpm: (S,) drive-pulley speeds (rpm, traceable;
    default :func:`sample_rpm`).  Static state at the scene's own speed: qi, q, inst, wrap_deg
    (n,), tensions_N (n,), span_lengths_m (n,), hub_N (n, 2), arm_deg (), gaps_m (pairs,)
    rim-to-rim distances of every two route entries; at each speed of ``rpm``: qi_speeds (S,
    n_i), freqs_hz (S, n_i) sorted, span_weights (S, n_i) (each sorted mode's weight as a span
    mode there, :mod:`beltjax.optimize.modes`; 1 when no objective watches "span"), good (S,)
    (equilibrium converged and stable); span_force_N (S + 1, n): each span's force on the
    pulleys, tension - rhoA c^2 lam (:func:`beltjax.critical.span_forces`), at the scene's own
    speed and each speed of ``rpm``; with a min_slip_margin constraint, slip_margins (one per
    route entry with a friction coefficient); feasible: belt fitted, every equilibrium
    converged and stable, every span force positive (no span past its critical speed),
    everything finite.  Every state is the operating point when the scene has lasting loads
    (:func:`beltjax.drive.lasting_loads`), else the unloaded state.
    """
    rpm = jnp.asarray(sample_rpm(problem) if rpm is None else rpm, dtype=jnp.float64)
    sc = parameters.set_values(scene, dict(zip(problem.paths, x)))
    inst = statics.install(sc)
    nr = drive_modal.n_rigid_modes(sc)
    gyro = effects_of(sc).moving_belt
    span = _watches_span(problem)
    v_rigid = drive_modal.rigid_mode(sc, inst)

    loaded = drive.lasting_loads(sc)  # the operating point under the mean loads

    def at(v):
        qv, at_v, iv = statics.equilibrium(sc, inst, speed=v, loaded=loaded)  # at_v: with its running creep
        force = critical.span_forces(sc, qv, at_v, v)  # <= 0: at or past the critical speed
        if rpm.shape[0] == 0:
            return qv, jnp.zeros(0), jnp.zeros(0), iv[0] > 0.5, force, at_v.creep
        if span:
            M, G, K = drive_modal.linearise(qv, sc, at_v, v)
            J = jax.jacfwd(lambda y: drive.full_coordinates(y, sc, at_v))(qv)
            stable, f, w = modes.frequencies_and_span_weights(M, G, K, J, nr, gyro, v_rigid, sc, at_v)
        else:
            stable, f, *_ = drive_modal.frequencies_about(sc, qv, at_v, v, gyro)
            w = jnp.ones_like(f)
        return qv, f, w, stable & (iv[0] > 0.5), force, at_v.creep

    # the static state (the scene's own speed) and every sampled speed through one equilibrium
    # solver in the compiled function (a second copy of the Newton loop and its implicit
    # derivative cost ~20 % more compile time); lax.map: see the module docstring
    v0 = drive.belt_speed(sc)
    speeds = jnp.concatenate([jnp.reshape(v0, (1,)), drive.belt_speed(sc, rpm)])
    qs, freqs, weights, good, force, creeps = jax.lax.map(at, speeds)
    inst = inst._replace(creep=creeps[0])  # the static state's, at the scene's own speed
    if rpm.shape[0] == 0:
        freqs = weights = jnp.zeros((1, drive.n_independent(sc)))
    qi = qs[0]
    q = drive.full_coordinates(qi, sc, inst)
    _, theta = drive.angles_and_arm(qi, sc, inst)
    tensions = drive.span_tensions(q, sc, inst)
    c, r = inst.centers, inst.radii
    wraps = drive.wraps(qi, sc, inst)  # of the solved layout (an arm's swing turns them)
    m = dict(
        wrap_deg=jnp.degrees(wraps), tensions_N=tensions, span_lengths_m=drive.full_span_lengths(q, sc),
        hub_N=drive.hub_forces(q, sc, inst, v0), arm_deg=jnp.degrees(theta),
        gaps_m=jnp.stack([jnp.linalg.norm(c[i] - c[j]) - r[i] - r[j] for i, j in _pairs(len(r))]),
        freqs_hz=freqs[1:], span_weights=weights[1:], qi_speeds=qs[1:], good=good[1:], span_force_N=force,
        qi=qi, q=q,
    )
    faults = {**statics.installation_faults(sc, inst), **statics.operating_faults(sc, qi, inst)}
    ok = (~jnp.any(jnp.stack(list(faults.values())))
          & jnp.all((wraps > 0) & (wraps < 2 * jnp.pi)) & jnp.all(good) & jnp.all(tensions > 0)
          & jnp.all(force > 0) & ~couplings.static_overrun(qi, sc, inst))
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in m.values()]))
    if any(c.kind == "min_slip_margin" for c in problem.constraints):  # the arcs' slip margins (capstan law)
        m["slip_margins"] = friction.arc_margins(sc, force[0], wraps)[1]
        ok = ok & jnp.all(jnp.isfinite(m["slip_margins"]))
    motion = [o for o in problem.objectives if o.kind == "arm_motion"]
    if motion:  # the periodic steady state over each band (beltjax.orders): the arm's peak-to-peak
        from beltjax.orders import SETTLE_TOL, over_speed

        runs = [over_speed(sc, {}, jnp.linspace(o.rpm[0], o.rpm[1], o.speeds), o.settle_s, o.response)
                for o in motion]
        m["arm_p2p_deg"] = jnp.concatenate([r["arm_angle_deg:p2p"] for r in runs])  # the bands' speeds in turn
        ok = ok & jnp.all(jnp.stack([jnp.all(r["solver_ok"] > 0.5) for r in runs]))
        # a speed without a periodic state (no attracting cycle, a transient not settled): not a feasible point
        ok = ok & jnp.all(jnp.stack([jnp.all(r["settling"] <= SETTLE_TOL) for r in runs]))
        ok = ok & jnp.all(jnp.isfinite(m["arm_p2p_deg"]))
    m["inst"] = inst
    m["feasible"] = ok & finite
    return m


def mode_masks(problem: Problem, labels: list | None, n_modes: int, n_rigid: int) -> np.ndarray:
    """(n_resonance_objectives, n_modes) 0/1 weights of the sorted modes each resonance objective
    may watch: "all" and "span" every flexible mode (for "span" the per-speed span weights of
    :func:`measures` then choose among them), N the N lowest flexible ones.  ``labels`` is not
    used (it served the earlier selection by the labels at the band's lowest speed)."""
    out = np.zeros((len(_bands(problem)), n_modes))
    for j, o in enumerate(_bands(problem)):
        if o.modes in ("all", "span"):
            out[j, n_rigid:] = 1.0
        else:
            out[j, n_rigid:n_rigid + int(o.modes)] = 1.0
    return out


def problem_masks(scene: Scene, problem: Problem) -> np.ndarray:
    """:func:`mode_masks` of ``problem`` on ``scene`` (its number of modes and of rigid modes)."""
    return mode_masks(problem, None, drive.n_independent(scene), drive_modal.n_rigid_modes(scene))


def _soft_max(a, axis):
    return SOFT_HZ * jax.scipy.special.logsumexp(a / SOFT_HZ, axis=axis)


def band_need(freqs, rpm, orders, margin, soft: bool = True, weights=None):
    """Shift (Hz) each mode still needs to clear each order line over a speed band.

    freqs (K, m) Hz at the sampled speeds rpm (K,); orders (o,); weights (K, m) or None (all 1):
    how much each sorted mode counts at each speed (0: not watched there).  Returns (o, m):
    min(max_s(g + margin), max_s(margin - g))^+ with g = f - k rpm / 60, the max over the speeds
    where the mode is watched.  ``soft`` (JAX): each max is a weighted log-sum-exp
    SOFT_HZ log(sum_s w_s exp(a_s / SOFT_HZ)) (w = 1: the plain one, which errs on the safe
    side; w -> 0 drops the speed continuously); otherwise (numpy) the exact max over the speeds
    where the mode is watched (w = 1, :data:`WATCHED`).  A mode watched at no speed needs nothing.
    """
    xp = jnp if soft else np
    line = xp.asarray(orders)[:, None] * xp.asarray(rpm)[None, :] / 60.0  # (o, K)
    g = xp.asarray(freqs)[None, :, :] - line[:, :, None]  # (o, K, m)
    w = xp.broadcast_to(xp.ones(()) if weights is None else xp.asarray(weights), g.shape[1:])
    if soft:
        watched = jnp.any(w > 0, axis=0)  # (m,); the where's keep the gradient finite elsewhere
        b = jnp.where(watched[None, :], w, 1.0)[None]
        down = SOFT_HZ * jax.scipy.special.logsumexp((g + margin) / SOFT_HZ, axis=1, b=b)
        up = SOFT_HZ * jax.scipy.special.logsumexp((margin - g) / SOFT_HZ, axis=1, b=b)
        return jnp.where(watched[None, :], jnp.maximum(jnp.minimum(down, up), 0.0), 0.0)
    sel = (w >= WATCHED)[None]
    down = np.max(np.where(sel, g + margin, -np.inf), axis=1)
    up = np.max(np.where(sel, margin - g, -np.inf), axis=1)
    return np.maximum(np.minimum(down, up), 0.0)


def band_weights(m: dict, problem: Problem, masks, j: int, sl: slice, xp=jnp):
    """(K, m) weights of the sorted modes resonance objective j watches at its sampled speeds
    ``sl`` of :func:`measures` ``m``: its mask row, times the span weights with "span"."""
    w = xp.asarray(masks)[j][None, :]
    if _bands(problem)[j].modes == "span":
        w = w * xp.asarray(m["span_weights"])[sl]
    return w


def _violations(c: Constraint, m: dict, scene: Scene, xp=jnp):
    """Per-element violations (constraint units, >= 0) and the reported value of a constraint."""
    if c.kind == "min_wrap_deg":
        w = m["wrap_deg"] if c.where is None else m["wrap_deg"][scene.route.order.index(c.where)][None]
        return xp.maximum(c.lower - w, 0.0), xp.min(w)
    if c.kind == "no_overlap":
        return xp.maximum(c.lower - m["gaps_m"], 0.0), xp.min(m["gaps_m"])
    if c.kind == "min_slip_margin":
        s = m["slip_margins"]
        if c.where is not None:
            s = s[[scene.route.order[i] for i in friction.given(scene)].index(c.where)][None]
        return xp.maximum(c.lower - s, 0.0), xp.min(s)
    if c.kind == "static_tension":
        v = m["tensions_N"] if c.where is None else m["tensions_N"][scene.route.span_names.index(c.where)][None]
    else:
        v = xp.reshape(m["arm_deg"], (1,))
    lo = xp.maximum(c.lower - v, 0.0) if c.lower is not None else xp.zeros_like(v)
    hi = xp.maximum(v - c.upper, 0.0) if c.upper is not None else xp.zeros_like(v)
    value = (xp.min(v), xp.max(v)) if c.kind == "static_tension" else v[0]
    return xp.concatenate([lo, hi]), value


def term_names(problem: Problem) -> list[str]:
    """Names of the loss terms: "objective[i] kind" then "constraint[j] kind"."""
    return ([f"objective[{i}] {o.kind}" for i, o in enumerate(problem.objectives)]
            + [f"constraint[{j}] {c.kind}" for j, c in enumerate(problem.constraints)])


def terms_from_measures(m: dict, scene: Scene, problem: Problem, masks, rpm=None, soft: bool = True) -> dict:
    """The loss terms (name -> scalar) from :func:`measures` (JAX, or numpy with soft=False).

    masks: :func:`mode_masks`; rpm: the speeds the frequencies were computed at (default
    :func:`sample_rpm`).  A resonance term is weight * sum(need^2) (Hz^2, :func:`band_need`
    with :func:`band_weights`), a hub load
    weight * |F| (N), an arm motion weight * the arm's largest peak-to-peak over its band (deg), a
    constraint weight * sum((violation / unit)^2).
    """
    xp = jnp if soft else np
    rpm = sample_rpm(problem) if rpm is None else rpm
    out, j, k_motion = {}, 0, 0
    names = term_names(problem)
    starts = _band_starts(problem)
    for i, o in enumerate(problem.objectives):
        if o.kind == "resonance_band":
            sl = slice(starts[j], starts[j] + o.speeds)
            w = band_weights(m, problem, masks, j, sl, xp)
            need = band_need(m["freqs_hz"][sl], rpm[sl], np.asarray(o.orders), o.margin_hz, soft, w)
            out[names[i]] = o.weight * xp.sum(need**2)
            j += 1
        elif o.kind == "arm_motion":  # the largest peak-to-peak over the band's speeds (deg)
            out[names[i]] = o.weight * xp.max(m["arm_p2p_deg"][k_motion:k_motion + o.speeds])
            k_motion += o.speeds
        else:
            F = m["hub_N"][scene.route.order.index(o.pulley)]
            out[names[i]] = o.weight * xp.sqrt(xp.sum(F**2))
    for k, c in enumerate(problem.constraints):
        viol, _ = _violations(c, m, scene, xp)
        out[names[len(problem.objectives) + k]] = c.weight * xp.sum((viol / _UNIT[c.kind]) ** 2)
    return out


def loss_terms(scene: Scene, problem: Problem, x, masks):
    """(terms dict name -> scalar, feasible) at parameter values x (file units); pure JAX.

    masks: :func:`mode_masks` of the resonance objectives (:func:`problem_masks`).
    """
    m = measures(scene, problem, x)
    return terms_from_measures(m, scene, problem, masks), m["feasible"]


def loss(scene: Scene, problem: Problem, x, masks):
    """Total loss (objective terms + penalties) at x (file units); NaN where infeasible.

    Pure JAX: jit-, grad-able in x (and in every number of ``scene``).
    """
    terms, ok = loss_terms(scene, problem, x, masks)
    total = sum(terms.values())
    return jnp.where(ok, total, jnp.nan)


def _loss_key(problem: Problem) -> Problem:
    """The part of a problem the loss depends on (optimiser settings cleared): the cache key of
    :func:`_compiled`, so that runs differing only in steps or learning rate share one compile."""
    objectives = tuple(dataclasses.replace(o, tolerance_hz=0.0) for o in problem.objectives)
    return dataclasses.replace(problem, objectives=objectives, steps=1, learning_rate=1.0, tolerance=0.0, patience=1,
                               elements_per_span=None, description="", min_steps=0, starts=1)


@functools.lru_cache(maxsize=16)
def _compiled(problem: Problem):
    """Jitted f(z, scene, rpm, masks) -> ((loss, (terms, measures)), d loss / d z), z = x / scale.

    rpm and masks are arguments, so the same compiled function also gives the frequencies
    over a Campbell grid (in chunks of len(rpm)); the selection of "span" is made inside."""
    scales = jnp.asarray(problem.scales)

    def f(z, scene, rpm, masks):
        m = measures(scene, problem, z * scales, rpm)
        terms = terms_from_measures(m, scene, problem, masks, rpm)
        total = sum(terms.values())
        return jnp.where(m["feasible"], total, jnp.nan), (terms, m)

    return jax.jit(jax.value_and_grad(f, has_aux=True))


@functools.lru_cache(maxsize=16)
def _measures_jit(problem: Problem):
    """Jitted measures(scene, x, rpm) (no gradient): the check on a finer mesh."""
    return jax.jit(lambda scene, x, rpm: measures(scene, problem, x, rpm))
