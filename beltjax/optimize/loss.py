"""The pure-JAX loss: measures of a layout, the resonance and constraint terms, the compiled value and gradient."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import drive, drive_modal, parameters, statics
from beltjax.scene import Scene
from beltjax.optimize.problem import (_UNIT, Constraint, OptimizeError, Problem, SOFT_HZ, _band_starts, _bands, _pairs,
                                      sample_rpm)


def measures(scene: Scene, problem: Problem, x, rpm=None) -> dict:
    """Every quantity the objectives and constraints use, at parameter values ``x`` (pure JAX).

    x: (n_variables,) values in file units; rpm: (S,) drive-pulley speeds (rpm, traceable;
    default :func:`sample_rpm`).  Static state at the scene's own speed: qi, q, inst, wrap_deg
    (n,), tensions_N (n,), span_lengths_m (n,), hub_N (n, 2), arm_deg (), gaps_m (pairs,)
    rim-to-rim distances of every two route entries; at each speed of ``rpm``: qi_speeds (S,
    n_i), freqs_hz (S, n_i) sorted, good (S,) (equilibrium converged and stable); feasible:
    belt fitted, every equilibrium converged and stable, spans taut, everything finite.
    """
    rpm = jnp.asarray(sample_rpm(problem) if rpm is None else rpm, dtype=jnp.float64)
    sc = parameters.set_values(scene, dict(zip(problem.paths, x)))
    inst = statics.install(sc)
    nr = drive_modal.n_rigid_modes(sc)
    gyro = sc.model.has("transport")

    def at(v):
        qv, _, iv = statics.equilibrium(sc, inst, speed=v)
        if rpm.shape[0] == 0:
            return qv, jnp.zeros(0), iv[0] > 0.5
        M, G, K = drive_modal.linearise(qv, sc, inst, v)
        stable, f = drive_modal.frequencies_from_matrices(M, G, K, nr, gyro, drive_modal.rigid_mode(sc, inst))
        return qv, f, stable & (iv[0] > 0.5)

    # the static state (the scene's own speed) and every sampled speed through one equilibrium
    # solver in the compiled function (a second copy of the Newton loop and its implicit
    # derivative cost ~20 % more compile time); lax.map: see the module docstring
    v0 = drive.belt_speed(sc)
    speeds = jnp.concatenate([jnp.reshape(v0, (1,)), drive.belt_speed(sc, rpm)])
    qs, freqs, good = jax.lax.map(at, speeds)
    if rpm.shape[0] == 0:
        freqs = jnp.zeros((1, drive.n_independent(sc)))
    qi = qs[0]
    q = drive.full_coordinates(qi, sc, inst)
    _, theta = drive.angles_and_arm(qi, sc, inst)
    tensions = drive.span_tensions(q, sc, inst)
    c, r = inst.centers, inst.radii
    m = dict(
        wrap_deg=jnp.degrees(inst.wrap), tensions_N=tensions, span_lengths_m=drive.full_span_lengths(q, sc),
        hub_N=drive.hub_forces(q, sc, inst, v0), arm_deg=jnp.degrees(theta),
        gaps_m=jnp.stack([jnp.linalg.norm(c[i] - c[j]) - r[i] - r[j] for i, j in _pairs(len(r))]),
        freqs_hz=freqs[1:], qi_speeds=qs[1:], good=good[1:], qi=qi, q=q,
    )
    lam = inst.stretch
    ok = (jnp.isfinite(inst.arm_angle) & (lam > 1.0) & (lam - 1.0 <= statics.MAX_INSTALL_STRAIN)
          & jnp.all((inst.wrap > 0) & (inst.wrap < 2 * jnp.pi)) & jnp.all(good) & jnp.all(tensions > 0))
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in m.values()]))
    m["inst"] = inst
    m["feasible"] = ok & finite
    return m


def mode_masks(problem: Problem, labels: list | None, n_modes: int, n_rigid: int) -> np.ndarray:
    """(n_resonance_objectives, n_modes) 0/1 weights of the sorted modes each resonance objective
    watches: "all" every flexible mode, N the N lowest flexible ones, "span" the modes labelled
    transverse (``labels[j]``: the labels at objective j's lowest speed)."""
    out = np.zeros((len(_bands(problem)), n_modes))
    for j, o in enumerate(_bands(problem)):
        if o.modes == "all":
            out[j, n_rigid:] = 1.0
        elif o.modes == "span":
            out[j] = [1.0 if "transverse" in lab else 0.0 for lab in labels[j]]
        else:
            out[j, n_rigid:n_rigid + int(o.modes)] = 1.0
    return out


def _soft_max(a, axis):
    return SOFT_HZ * jax.scipy.special.logsumexp(a / SOFT_HZ, axis=axis)


def band_need(freqs, rpm, orders, margin, soft: bool = True):
    """Shift (Hz) each mode still needs to clear each order line over a speed band.

    freqs (K, m) Hz at the sampled speeds rpm (K,); orders (o,).  Returns (o, m):
    min(max_s(g + margin), max_s(margin - g))^+ with g = f - k rpm / 60; the max over speeds
    is a log-sum-exp (temperature SOFT_HZ) when ``soft``, exact otherwise (numpy or JAX).
    """
    xp = jnp if soft else np
    line = xp.asarray(orders)[:, None] * xp.asarray(rpm)[None, :] / 60.0  # (o, K)
    g = xp.asarray(freqs)[None, :, :] - line[:, :, None]  # (o, K, m)
    if soft:
        down, up = _soft_max(g + margin, 1), _soft_max(margin - g, 1)
    else:
        down, up = np.max(g + margin, axis=1), np.max(margin - g, axis=1)
    return xp.maximum(xp.minimum(down, up), 0.0)


def _violations(c: Constraint, m: dict, scene: Scene, xp=jnp):
    """Per-element violations (constraint units, >= 0) and the reported value of a constraint."""
    if c.kind == "min_wrap_deg":
        w = m["wrap_deg"] if c.where is None else m["wrap_deg"][scene.route.order.index(c.where)][None]
        return xp.maximum(c.lower - w, 0.0), xp.min(w)
    if c.kind == "no_overlap":
        return xp.maximum(c.lower - m["gaps_m"], 0.0), xp.min(m["gaps_m"])
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
    :func:`sample_rpm`).  A resonance term is weight * sum(mask * need^2) (Hz^2), a hub load
    weight * |F| (N), a constraint weight * sum((violation / unit)^2).
    """
    xp = jnp if soft else np
    rpm = sample_rpm(problem) if rpm is None else rpm
    out, j = {}, 0
    names = term_names(problem)
    starts = _band_starts(problem)
    for i, o in enumerate(problem.objectives):
        if o.kind == "resonance_band":
            sl = slice(starts[j], starts[j] + o.speeds)
            need = band_need(m["freqs_hz"][sl], rpm[sl], np.asarray(o.orders), o.margin_hz, soft)
            out[names[i]] = o.weight * xp.sum(xp.asarray(masks)[j] * need**2)
            j += 1
        else:
            F = m["hub_N"][scene.route.order.index(o.pulley)]
            out[names[i]] = o.weight * xp.sqrt(xp.sum(F**2))
    for k, c in enumerate(problem.constraints):
        viol, _ = _violations(c, m, scene, xp)
        out[names[len(problem.objectives) + k]] = c.weight * xp.sum((viol / _UNIT[c.kind]) ** 2)
    return out


def loss_terms(scene: Scene, problem: Problem, x, masks):
    """(terms dict name -> scalar, feasible) at parameter values x (file units); pure JAX.

    masks: :func:`mode_masks` of the resonance objectives (needed with modes = "span": the
    labels come from :func:`mode_labels`).
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
    return dataclasses.replace(problem, steps=1, learning_rate=1.0, tolerance=0.0, patience=1,
                               elements_per_span=None, description="")


@functools.lru_cache(maxsize=16)
def _compiled(problem: Problem):
    """Jitted f(z, scene, rpm, masks) -> ((loss, (terms, measures)), d loss / d z), z = x / scale.

    rpm and masks are arguments, so the same compiled function also gives the frequencies
    over a Campbell grid (in chunks of len(rpm)) and takes the mode selection of "span"."""
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


def mode_labels(scene: Scene, qi, inst, rpm: float) -> list[str] | None:
    """Labels of the modes of ``scene`` about the equilibrium (qi, inst) at drive-pulley speed
    ``rpm`` (see :func:`beltjax.drive_modal.label_modes`); None if unstable there.

    The shapes are those of (M, K) at that steady motion (centrifugal stiffness included, the
    gyroscopic coupling left out): real shapes, whose half-waves count reliably, and the same
    sorted order as the gyroscopic frequencies unless two modes nearly coincide."""
    sc = drive.canonical(scene)
    v = float(drive.belt_speed(sc, rpm))
    qi = jnp.asarray(qi)
    out = drive_modal.modes_at(sc, qi, inst, v, False)
    if not bool(out["stable"]):
        return None
    labels, _ = drive_modal.label_modes(out["freqs"], out["shapes"], qi, sc, inst, out["J"])
    return labels


def _labels_and_masks(scene: Scene, problem: Problem, m: dict) -> tuple[list, np.ndarray]:
    """Labels at each resonance objective's lowest sampled speed and the mode masks, from a
    :func:`measures` result ``m`` (numpy)."""
    rpm, labels = sample_rpm(problem), []
    for o, k in zip(_bands(problem), _band_starts(problem)):
        lab = mode_labels(scene, m["qi_speeds"][k], m["inst"], float(rpm[k]))
        if lab is None:
            raise OptimizeError(f"the drive is unstable at {rpm[k]:g} rpm",
                                f"objective[{problem.objectives.index(o)}].rpm")
        labels.append(lab)
    n = drive.n_independent(scene)
    masks = mode_masks(problem, labels, n, drive_modal.n_rigid_modes(scene))
    for j, o in enumerate(_bands(problem)):
        if not masks[j].any():
            raise OptimizeError(f"no mode is selected by modes = {o.modes!r}",
                                f"objective[{problem.objectives.index(o)}].modes")
    return labels, masks
