"""Modal fit: scene parameters from measured natural frequencies, by gradients through statics
and the modal analysis.

Dataset section (paths relative to the dataset file)::

    [modal]
    parameters = ["belt.EI", "belt.length"]   # beltjax.parameters paths to fit
    per_configuration = ["belt.length"]        # of those, the ones with one value per configuration
    # frequency_std_hz = 0.5                   # measurement standard deviation (Hz); default:
    #                                          # estimated from the residuals (s^2 = SSR / (m - p))
    # max_iterations = 50
    [[modal.configuration]]
    name = "T200"
    scene = "../../../scenes/two_pulley_T200.toml"
    modes = [
      { label = "1st transverse", frequency_hz = 30.0 },
      { label = "1st rotational", frequency_hz = 96.0 },
      { label = "2nd transverse", span = "crank-alternator", frequency_hz = 60.6 },
    ]

Matching.  A measured mode's label gives an order and a kind ("1st transverse", "2nd
rotational", "3rd longitudinal"; "rigid body" modes are skipped) and, optionally (key
``span``), the span it lives in.  The model modes of the starting parameters (labelled by
:func:`beltjax.drive_modal.analyse_modes`) with that order and kind (and span) are the
candidates; the one nearest in frequency is chosen, together with every candidate within
0.5 % of it: two spans at one tension give every transverse frequency twice, and the model
value is the *mean* of that group.  A symmetric function of a repeated group has an exact
gradient, whereas one eigenvalue of a repeated pair has a basis-dependent one (DESIGN.md).
After the fit the modes are labelled again; if a match moved, the fit is repeated from there.

Fit.  Positive parameters are fitted in log space, others in units of their starting
magnitude; the loss is 1/2 sum(((f_model - f_measured) / sigma)^2), minimised by
Levenberg-Marquardt on the exact Jacobian (forward mode through the implicit differentiation
of the statics and the symmetric eigenvalues; :func:`_solve` says why not optax).
Configurations with the same structure are evaluated
in one ``vmap``.  Standard errors come from the Jacobian of the residuals at the optimum,
``cov = s^2 (J^T J)^-1`` (s = frequency_std_hz, or estimated from the residuals); a Jacobian
whose scaled columns are (nearly) dependent is reported as the parameters that cannot be told
apart, never returned as a fit.
"""

from __future__ import annotations

import pathlib
import time
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import drive, drive_modal, parameters, statics
from beltjax.scene import Scene
from beltjax.tomltable import show
from identification import least_squares
from identification.data import DataError
from identification.modal_problem import (MAX_ITERATIONS, _CONF_KEYS, _KEYS, _LABEL, _POSITIVE, Configuration, Measured,  # noqa: F401
                                         Problem, _fail, _parse_configuration, _parse_mode, _start_value,
                                         _strings, parse)

#: candidates within this relative distance of the chosen one form its repeated group
GROUP_RTOL = 5e-3
#: a measured mode farther than this (relative) from every candidate has no matching mode ...
MATCH_RTOL = 0.3
#: ... unless it has one candidate only (its label and order name one model mode: nothing to
#: confuse it with), which matches up to this distance: e.g. the tensioner bench's 1st rotational
#: mode, 35 % low at the printed inputs before the fit moves the arm (the modal dataset's README)
MATCH_RTOL_UNIQUE = 0.5
#: a Levenberg-Marquardt round ends when a step moves the fitted values (relative units) and every
#: residual by less than STEP_ATOL + STALL_RTOL times their size (optimistix's Cauchy test), or when
#: the Gauss-Newton step could lower the loss by less than STALL_RTOL of it
STALL_RTOL, STEP_ATOL = 1e-6, 1e-9
#: matching rounds at most (the modes are matched again after each round while the matches move)
MAX_ROUNDS = 3
#: smallest accepted ratio of the scaled Jacobian's singular values (identifiability)
IDENTIFIABLE_RCOND = 1e-6


# --------------------------------------------------------------------------- reading


# --------------------------------------------------------------------------- the problem


@dataclass
class _Layout:
    """Where each fitted value sits in the vector x, and how it maps to the parameter."""

    names: list[str]          # one per entry of x: "belt.EI" or "belt.length@T200"
    index: np.ndarray         # (n_conf, n_paths) -> entry of x
    log: np.ndarray           # (n_x,) bool
    p0: np.ndarray            # (n_x,) starting values (file units)


def _layout(problem: Problem) -> _Layout:
    confs = problem.configurations
    names, log, p0 = [], [], []
    index = np.zeros((len(confs), len(problem.paths)), dtype=int)
    for j, path in enumerate(problem.paths):
        starts = [_start_value(c.scene, path) for c in confs]
        if path in problem.per_configuration:
            for i, c in enumerate(confs):
                index[i, j] = len(names)
                names.append(f"{path}@{c.name}")
                p0.append(starts[i])
        else:
            index[:, j] = len(names)
            names.append(path)
            p0.append(float(np.mean(starts)))
        for _ in range(len(confs) if path in problem.per_configuration else 1):
            log.append(bool(_POSITIVE.match(path)))
    p0 = np.asarray(p0)
    log = np.asarray(log) & (p0 > 0)
    return _Layout(names, index, log, p0)


def _to_params(x, lay: _Layout):
    scale = jnp.where(lay.p0 != 0, jnp.abs(lay.p0), 1.0)
    return jnp.where(lay.log, lay.p0 * jnp.exp(x), lay.p0 + scale * x)


# --------------------------------------------------------------------------- matching


def _candidates(labels, m: Measured) -> list[int]:
    out = []
    for k, lab in enumerate(labels):
        hit = _LABEL.match(lab)
        if hit and int(hit.group(1)) == m.order and hit.group(2).lower() == m.kind:
            if m.span is None or m.span in lab:
                out.append(k)
    return out


def match(freqs, labels, modes: list[Measured], conf_key: str = "") -> np.ndarray:
    """Averaging weights W (n_measured, n_model): row i averages the model modes matched to
    measured mode i (the nearest candidate by label and its repeated group)."""
    freqs = np.asarray(freqs)
    W = np.zeros((len(modes), len(freqs)))
    for i, m in enumerate(modes):
        cand = _candidates(labels, m)
        if not cand:
            kinds = sorted({lab for lab in labels if lab != "rigid body"}, key=labels.index)[:8]
            raise DataError(f"no model mode labelled {show(m.label)}"
                            f"{' in span ' + m.span if m.span else ''} (model modes: {'; '.join(kinds)} ...)", m.key)
        k = min(cand, key=lambda c: abs(freqs[c] - m.frequency_hz))
        rtol = MATCH_RTOL_UNIQUE if len(cand) == 1 else MATCH_RTOL
        if abs(freqs[k] - m.frequency_hz) > rtol * m.frequency_hz:
            raise DataError(f"{m.label} at {m.frequency_hz:g} Hz has no matching model mode: the nearest "
                            f"{m.kind} mode of order {m.order} is at {freqs[k]:.4g} Hz", m.key)
        group = [c for c in cand if abs(freqs[c] - freqs[k]) <= GROUP_RTOL * freqs[k]]
        W[i, group] = 1.0 / len(group)
    return W


def _labelling_scene(scene: Scene, paths, values) -> Scene:
    """``scene`` with the fitted values, in the scene's own belt mode: a fitted length on a
    scene given by its tension goes back as the tension it installs (same physics, and the
    labelling reuses the functions compiled for the scene as loaded)."""
    values = dict(zip(paths, (float(v) for v in values)))
    length = values.pop("belt.length", None)
    s = parameters.set_values(scene, values)
    if length is not None:
        if scene.belt.length is None:
            inst = statics.install_compiled(drive.canonical(parameters.set_value(s, "belt.length", length)))
            s = parameters.set_value(s, "belt.static_tension", float(inst.tension))
        else:
            s = parameters.set_value(s, "belt.length", length)
    return s


def _modes_of(scene: Scene):
    res = drive_modal.analyse_modes(scene)
    if not res.stable:
        raise DataError(f"{scene.source}: the drive is unstable at these parameters", "modal")
    return res.frequencies_hz, res.labels


# --------------------------------------------------------------------------- model


def _groups(problem: Problem):
    """Configurations grouped by identical structure (one vmap each): list of index lists."""
    groups: list[list[int]] = []
    sigs = []
    for i, c in enumerate(problem.configurations):
        sig = jax.tree.structure(drive.canonical(c.scene))
        for g, s in zip(groups, sigs):
            if s == sig:
                g.append(i)
                break
        else:
            groups.append([i])
            sigs.append(sig)
    return groups


def _stack(scenes):
    return jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *scenes)


def _model_frequencies(scene: Scene, values, paths):
    s = parameters.set_values(scene, dict(zip(paths, values)))
    return drive_modal.frequencies(s)


@dataclass
class ModalFit:
    """Result of a modal fit (SI / scene-file units); see :func:`fit_modal`."""

    names: list[str]
    values: np.ndarray
    start: np.ndarray
    std_errors: np.ndarray
    correlation: np.ndarray
    modes: list[dict]              # per measured mode: configuration, label, measured, before, after
    loss_history: list[float]
    sigma_hz: float
    sigma_estimated: bool
    iterations: int
    rounds: int
    wall_s: float
    paths: list[str] = field(default_factory=list)

    @property
    def rms_residual_hz(self) -> float:
        """Root mean square of the frequency residuals after the fit (Hz)."""
        r = np.array([m["residual_hz"] for m in self.modes])
        return float(np.sqrt(np.mean(r**2)))

    def to_json(self) -> dict:
        """fit.json contents of the modal section."""
        return {
            "parameters": {n: {"value": float(v), "start": float(s), "std_error": float(e),
                               "relative_std_error": float(e / abs(v)) if v else None}
                           for n, v, s, e in zip(self.names, self.values, self.start, self.std_errors)},
            "correlation": {"names": self.names, "matrix": np.round(self.correlation, 6).tolist()},
            "modes": self.modes,
            "rms_residual_hz": self.rms_residual_hz,
            "frequency_std_hz": self.sigma_hz,
            "frequency_std_estimated_from_residuals": self.sigma_estimated,
            "optimizer": "optimistix Levenberg-Marquardt (exact forward-mode Jacobian)",
            "iterations": self.iterations,
            "matching_rounds": self.rounds,
            "loss_history": [float(x) for x in self.loss_history],
            "wall_s": self.wall_s,
        }

    def table(self) -> str:
        """Fitted parameters and per-mode residuals as text."""
        lines = [f"{'parameter':<34} {'start':>12} {'fitted':>12} {'std error':>10}"]
        for n, v, s, e in zip(self.names, self.values, self.start, self.std_errors):
            lines.append(f"{n:<34} {s:>12.6g} {v:>12.6g} {e:>10.3g}")
        lines.append("")
        lines.append(f"{'configuration':<14} {'mode':<22} {'measured':>9} {'before':>9} {'after':>9} {'resid':>7}  [Hz]")
        for m in self.modes:
            lines.append(f"{m['configuration'][:14]:<14} {m['label'][:22]:<22} {m['measured_hz']:>9.2f} "
                         f"{m['model_before_hz']:>9.2f} {m['model_after_hz']:>9.2f} {m['residual_hz']:>7.2f}")
        lines.append(f"rms residual {self.rms_residual_hz:.3g} Hz after {self.iterations} Levenberg-Marquardt "
                     f"iterations "
                     f"(sigma {self.sigma_hz:.3g} Hz{', from the residuals' if self.sigma_estimated else ''})")
        return "\n".join(lines)

    def scene_block(self) -> str:
        """Fitted values as scene-file lines (one block per configuration where they differ)."""
        out = [f"# modal fit: rms residual {self.rms_residual_hz:.3g} Hz"]
        for n, v, e in zip(self.names, self.values, self.std_errors):
            path, _, conf = n.partition("@")
            table, _, key = path.rpartition(".")
            where = f" (configuration {conf})" if conf else ""
            out.append(f"# [{table}]{where}\n{key} = {v:.8g}    # +- {e:.2g}")
        return "\n".join(out)

    def plot(self, out: pathlib.Path) -> list[pathlib.Path]:
        """modal_fit_residuals.png (residual bars per mode) and modal_fit_loss.png (convergence)."""
        from beltjax.plotting import literal, save, subplots

        files = []
        fig, ax = subplots(figsize=(max(6.0, 0.35 * len(self.modes) + 2), 4))
        x = np.arange(len(self.modes))
        before = [m["model_before_hz"] - m["measured_hz"] for m in self.modes]
        after = [m["residual_hz"] for m in self.modes]
        ax.bar(x - 0.2, before, 0.4, label="start", color="0.7")
        ax.bar(x + 0.2, after, 0.4, label="fitted", color="C0")
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xticks(x, [literal(f"{m['configuration']}: {m['label']}", 60) for m in self.modes], rotation=70,
                      ha="right", fontsize=7)
        ax.set_ylabel("model - measured [Hz]")
        ax.set_title("Modal fit: frequency residual per mode")
        ax.legend()
        files.append(out / "modal_fit_residuals.png")
        save(fig, files[-1], dpi=120)
        fig, ax = subplots(figsize=(5, 3.5))
        ax.semilogy(np.arange(len(self.loss_history)), self.loss_history, marker=".")
        ax.set_xlabel("Levenberg-Marquardt iteration")
        ax.set_ylabel("loss")
        ax.set_title("Modal fit: convergence")
        files.append(out / "modal_fit_loss.png")
        save(fig, files[-1], dpi=120)
        return files


def _residuals_pure(x, stacked, idx, Ws, f_meas, log, p0, sigma, paths):
    """Frequency residuals (model - measured) / sigma over all configuration groups."""
    scale = jnp.where(p0 != 0, jnp.abs(p0), 1.0)
    p = jnp.where(log, p0 * jnp.exp(x), p0 + scale * x)
    out = []
    for sc, ix, W, fm in zip(stacked, idx, Ws, f_meas):
        f = jax.vmap(lambda s, v: _model_frequencies(s, v, paths))(sc, p[ix])
        out.append((jnp.einsum("cmn,cn->cm", W, f) - fm).reshape(-1))
    return jnp.concatenate(out) / sigma


def _fixed(problem: Problem, lay: _Layout, groups) -> dict:
    """The residuals' arguments that stay fixed during a fit: stacked canonical scenes and
    parameter indices per group of like configurations, log flags, starting values, paths."""
    confs = problem.configurations
    return dict(stacked=tuple(_stack([drive.canonical(confs[i].scene) for i in g]) for g in groups),
                idx=tuple(jnp.asarray(lay.index[g]) for g in groups),
                log=jnp.asarray(lay.log), p0=jnp.asarray(lay.p0), paths=tuple(problem.paths))


def _pad(groups, confs, Wlist):
    """Per group: W (n_conf, m_max, n_freq) and measured (n_conf, m_max), zero-padded rows."""
    Ws, fms, masks, slots = [], [], [], []
    for g in groups:
        m_max = max(len(confs[i].modes) for i in g)
        n = Wlist[g[0]].shape[1]
        W = np.zeros((len(g), m_max, n))
        fm = np.zeros((len(g), m_max))
        mk = np.zeros((len(g), m_max), bool)
        for a, i in enumerate(g):
            k = len(confs[i].modes)
            W[a, :k] = Wlist[i]
            fm[a, :k] = [m.frequency_hz for m in confs[i].modes]
            mk[a, :k] = True
            slots += [(i, j) for j in range(k)]
        Ws.append(jnp.asarray(W))
        fms.append(jnp.asarray(fm))
        masks.append(mk.reshape(-1))
    return Ws, fms, np.concatenate(masks), slots


def _lsq_residual(x, a):
    """_residuals_pure with a = (stacked, idx, Ws, f_meas, log, p0, sigma, paths), for the
    least-squares layer (module level: like fits share one compilation)."""
    stacked, idx, Ws, f_meas, log, p0, sigma, paths = a
    return _residuals_pure(x, stacked, idx, Ws, f_meas, log, p0, sigma, paths)


def _solve(fixed: dict, x0, Ws, f_meas, sigma, max_steps: int, progress: bool = False):
    """Minimise 1/2 |r(x)|^2 from x0 by the fits' least-squares layer (optimistix
    Levenberg-Marquardt on the exact forward-mode Jacobian: one tangent per fitted value
    through statics and eigenvalues); a :class:`least_squares.Solution`.  ``max_steps = 0``
    gives the residuals and Jacobian at x0 from the same compiled program.

    x is already in relative units (log, or per starting magnitude), so the scaling is 1.
    Why not optax here: this is a small least-squares problem (a handful of values, tens of
    residuals) whose scales differ by 10^3 (a belt length moves frequencies far more than EI).
    Measured on the bench dataset: optax L-BFGS, even Jacobi-scaled, took ~6 s per iteration
    (reverse mode through the statics inside its line search) and >100 iterations; LM takes
    ~0.3 s per step and converges in 2-3.  The tensile fit uses optax L-BFGS first, where its
    model is cheap and the starts are many."""
    from beltjax.progress import Reporter

    a = (fixed["stacked"], fixed["idx"], tuple(Ws), tuple(f_meas), fixed["log"], fixed["p0"],
         jnp.asarray(sigma, dtype=jnp.float64), fixed["paths"])
    reporter = Reporter()  # progress on stderr

    def line(k, loss):
        if progress and k > 0:
            reporter.update(f"modal fit: LM {k:3d}  loss {loss:.6g}")

    with least_squares.reporting(line):
        sol = least_squares.solve(_lsq_residual, jnp.asarray(x0), a, jnp.ones(len(x0)), max_steps,
                                  history=MAX_ITERATIONS, rtol=STALL_RTOL, atol=STEP_ATOL, gain_rtol=STALL_RTOL,
                                  report=True)
    if progress and max_steps > 0:
        reporter.finish()
    return sol


def _unit_scale(x, lay: _Layout):
    """d params / d x times the parameter magnitudes: Jacobian columns per relative change."""
    p = np.asarray(_to_params(x, lay))
    dp_dx = np.where(lay.log, p, np.where(lay.p0 != 0, np.abs(lay.p0), 1.0))
    return np.where(p != 0, np.abs(p), 1.0) / dp_dx


def _identifiability(J, names):
    sv_u, s, vt = np.linalg.svd(J, full_matrices=False)
    if s.size == 0 or s[0] == 0 or s[-1] < IDENTIFIABLE_RCOND * s[0]:
        v = vt[-1]
        who = [names[k] for k in np.argsort(-np.abs(v)) if abs(v[k]) > 0.25]
        raise DataError(f"not identifiable from these modes: {', '.join(who)} "
                        f"(the frequencies do not change independently with "
                        f"{'it' if len(who) == 1 else 'them'}; fix or drop {'it' if len(who) == 1 else 'one'})", "modal.parameters")


def fit_modal(section: dict, base: pathlib.Path, key: str = "modal", progress: bool = False) -> ModalFit:
    """Fit scene parameters to measured natural frequencies (see the module docstring)."""
    t0 = time.perf_counter()
    problem = parse(section, base)
    confs = problem.configurations
    lay = _layout(problem)
    groups = _groups(problem)
    m_total = sum(len(c.modes) for c in confs)
    if m_total <= len(lay.names):
        raise DataError(f"{m_total} measured modes for {len(lay.names)} fitted values: "
                        "more modes than parameters are needed", "modal")
    fixed = _fixed(problem, lay, groups)
    x = jnp.zeros(len(lay.names))
    hist_all, rounds, iterations = [], 0, 0
    before = None
    # match at the start; refit while the matches move (at most MAX_ROUNDS rounds)
    Wlist = None
    sig0 = 1.0 if problem.sigma_hz is None else problem.sigma_hz

    for rounds in range(1, MAX_ROUNDS + 1):
        p = np.asarray(_to_params(x, lay))
        labelled = []
        for i, c in enumerate(confs):
            labelled.append(_modes_of(_labelling_scene(c.scene, problem.paths, p[lay.index[i]])))
        W_new = [match(f, lab, c.modes) for (f, lab), c in zip(labelled, confs)]
        if before is None:
            before = [W @ f for W, (f, _) in zip(W_new, labelled)]
        if Wlist is not None and all(np.array_equal(a != 0, b != 0) for a, b in zip(Wlist, W_new)):
            break
        Wlist = W_new
        Ws, fms, mask, slots = _pad(groups, confs, Wlist)

        if progress:
            from beltjax.progress import message

            message(f"modal fit: round {rounds}, {len(lay.names)} values, {m_total} modes")
        start = _solve(fixed, x, Ws, fms, sig0, 0)
        if not np.all(np.isfinite(np.asarray(start.residual))):
            raise DataError("the model cannot be evaluated at the starting values (NaN frequencies)", "modal")
        _identifiability(np.asarray(start.jacobian)[mask] * _unit_scale(x, lay), lay.names)
        sol = _solve(fixed, x, Ws, fms, sig0, problem.max_iterations, progress)
        x, n_it = sol.x, int(sol.steps)
        iterations += n_it
        hist_all += [float(v) for v in np.asarray(sol.loss)[: n_it + 1]]
    # statistics at the optimum (residuals in Hz: sigma = 1)
    Jx = sig0 * np.asarray(sol.jacobian)[mask]
    r = sig0 * np.asarray(sol.residual)[mask]
    p = np.asarray(_to_params(x, lay))
    dp_dx = np.where(lay.log, p, np.where(lay.p0 != 0, np.abs(lay.p0), 1.0))
    Jp = Jx / dp_dx  # d r / d p (Hz per unit)
    scale = np.where(p != 0, np.abs(p), 1.0)
    _identifiability(Jp * scale, lay.names)
    dof = len(r) - len(p)
    if problem.sigma_hz is None:
        sigma, estimated = float(np.sqrt(np.sum(r**2) / dof)) if dof > 0 else float("nan"), True
    else:
        sigma, estimated = problem.sigma_hz, False
    cov = sigma**2 * np.linalg.inv(Jp.T @ Jp)
    se = np.sqrt(np.diag(cov))
    corr = cov / np.outer(se, se)
    resid = dict(zip(slots, r))
    modes = []
    for i, c in enumerate(confs):
        for j, m in enumerate(c.modes):
            modes.append({"configuration": c.name, "label": m.label, "span": m.span,
                          "measured_hz": m.frequency_hz, "model_before_hz": float(before[i][j]),
                          "model_after_hz": float(m.frequency_hz + resid[i, j]),
                          "residual_hz": float(resid[i, j])})
    return ModalFit(lay.names, p, lay.p0, se, corr, modes, hist_all, sigma, estimated, iterations, rounds,
                    time.perf_counter() - t0, list(problem.paths))
