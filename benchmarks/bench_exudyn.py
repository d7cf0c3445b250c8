"""Peer comparison with Exudyn: the same ANCF problems solved by both tools in one run.

Run: ``python benchmarks/bench_exudyn.py`` (about 3 min; 2.7-4.4 min on the busy 2-core
machine); needs the ``benchmark`` extra (``pip install -e ".[benchmark]"``, which installs exudyn).  Writes
``benchmarks/results/exudyn.json`` and ``benchmarks/figures/exudyn_comparison.png``.  Without
exudyn it prints a message, writes a JSON that says ``"skipped": true`` and exits 0.

The problems are identical in both tools: the thesis' steel strip (L = 0.637 m,
EA = 210e9 * 2.25e-5 N, EI = 210e9 * 4.2188e-12 N m^2, rhoA = 7860 * 2.25e-5 kg/m, read from
``shared/reference/thesis_reference.json`` as tests/conftest.py does), the same number of
cubic ANCF elements (beltjax ``ancf``; Exudyn ``ObjectANCFCable2D`` / ``ObjectALEANCFCable2D``
on ``NodePoint2DSlope1`` nodes, the same 8 coordinates per element) and the same boundary
conditions (coordinates removed in both for the eigen-analyses).

(a) Cantilever (clamped-free, T = 0) eigen-analysis with 2-32 elements: first 4
    frequencies against the Euler-Bernoulli values f_n = (beta_n L)^2/(2 pi L^2)
    sqrt(EI/rhoA), cos(beta L) cosh(beta L) = -1.  beltjax: ``analyse_span`` (frequencies,
    labelled mode shapes) and the "jit core", one compiled call of ``span.span_matrices`` +
    ``modal.symmetric_modes`` (frequencies and mode shapes: what ``analyse_span`` computes
    before its eager post-processing); Exudyn: build + ``Assemble`` + ``ComputeODE2Eigenvalues``
    with the clamped coordinates as ``constrainedCoordinates`` (scipy ``eigh``, values and
    vectors).  beltjax's compile time: cold first call (after ``jax.clear_caches()``) minus
    the steady time for ``analyse_span``, lower + compile for the jit core.
(b) 1 s transient of the 10-element cantilever under a tip load step (-0.2 N in y from
    t = 0, from the straight state at rest; static tip deflection 19 mm, peak 39 mm:
    geometrically nonlinear, 6 % of L), no gravity, no damping.  Output: tip y displacement
    every 4 ms.  beltjax: ``dynamics.span_vector_field`` (the span's equations of motion)
    plus the constant tip force, integrated by diffrax with ``integrators.GeneralizedAlpha``
    set up as ``transient.simulate`` does it (modified Newton, Jacobian kept for
    ``transient.JACOBIAN_EVERY`` steps, tolerances ``transient.NEWTON_RTOL/ATOL``); step and
    rho_inf are traced, so one compilation serves every setting.  Exudyn: ``SolveDynamic``
    with its generalized-alpha solver (index-3 coordinate constraints at the clamp,
    modified Newton, fixed step: ``adaptiveStep`` off).  Exudyn's default Newton
    absoluteTolerance (1e-10) stalls at steps <= 5e-4 s here (the residual's round-off
    floor is ~2e-8 N), so it is set to 1e-7 N (errors unchanged, checked against beltjax).
    Reference: each tool at dt = 1e-3/128 s; the two references are compared.  Error: max
    over the samples of |y_tip - y_ref| divided by max |y_ref|.  Settings tried in both:
    rho_inf in {1, 0.9}, dt = 1e-3 / 2^k s; for each error level the cheapest setting
    that reaches it is re-timed round-robin (min of 3) and the times are compared.
(c) Pinned-pinned strip, T = 100 N, 20 elements, with axial transport at 0 to 0.99 of the
    critical speed sqrt(T/rhoA) = 23.8 m/s.  beltjax: ``analyse_span(speed=c)`` (gyroscopic
    modes by its skew-Hermitian route, labels, shapes) and the jit core (``span_matrices`` +
    ``modal._skew_modes``, the eigen-solve ``analyse_span`` runs, in one compiled call; at c = 0
    ``modal.symmetric_modes``, as ``analyse_span``).  Exudyn: ``ObjectALEANCFCable2D``
    elements sharing one ``NodeGenericODE2`` axial-velocity coordinate with the initial
    velocity c, a reference axial strain -T/EA (axial force T in the straight state), M, K
    and D from its static solver (the calls ``ComputeODE2Eigenvalues`` makes) with the ALE and
    pin coordinates removed, then its complex-eigenvalue algorithm (-inv(A) B and
    scipy ``eig``, values and vectors; at c = 0 its symmetric one, scipy ``eigh(K, M)``)
    re-written here with the reduced sizes because
    ``ComputeODE2Eigenvalues(computeComplexEigenvalues=True, constrainedCoordinates=...)``
    fails in exudyn 1.13.6 (it builds the zero blocks with the unreduced size).  beltjax's
    span is an exactly stretched ANCF span (stretch lam = 1.0000212); its transverse
    equation is the moving beam with rhoA/lam and EI lam^3 over the spatial length, so
    Exudyn gets those (both tools then discretise the same PDE).  Reference: the exact
    characteristic equation of the pinned-pinned tensioned, axially moving Euler-Bernoulli
    beam, EI b^4 + (T - m c^2) b^2 - 2 m c w b - m w^2 = 0, w = sum C_k exp(i b_k x),
    w = w'' = 0 at both ends, solved for w by complex secant iterations from the FEM values
    (at c = 0 it equals n/(2L) sqrt((T + EI (n pi/L)^2)/m) to 1e-15).
(d) 1000 tension variants (T = 50..150 N) of the (c) span at c = 10 m/s, first 6
    frequencies only.  beltjax: one jitted ``jax.vmap`` of ``span.span_matrices`` +
    ``modal.skew_frequencies`` (and, for comparison, the same under ``jax.lax.map``: one
    compiled call looping over the variants); Exudyn: a Python loop, rebuilding the model per
    variant, M, K, D as in (c) and ``numpy.linalg.eigvals`` of the companion matrix.  If
    the first 50 Exudyn variants project to more than EXUDYN_LOOP_BUDGET_S for 1000, the
    loop stops there and the time is extrapolated linearly (said in the output).

Equal accuracy: in (a), (c) and (d) both tools discretise with the same elements and get
the same frequencies (to about 1e-8 relative), so equal accuracy = equal mesh; in (b) the
cheapest setting of each tool that reaches the error level is compared.  Ratios are
Exudyn time / beltjax time (> 1: beltjax faster).

Timing: every time is taken after compilation and measured twice, as wall time and as the
process CPU time (``time.process_time``, all threads of the process: JAX's worker threads
count).  The machine is shared with other jobs (load average 3-5 on its 2 cores while this was
written): wall times then include waiting for a core, and that hurts beltjax more than Exudyn:
beltjax's XLA worker threads, which run its compiled code, are all pinned to one core (see
``thread_affinity``; recorded in the JSON), while Exudyn runs in the main thread, free to use
either core; wall-time ratios swing by 2-5x between samples.  The CPU time is the stable
measure of the work done; the headline ratios use it (medians of the round-robin samples for
the eigen-analyses, min of 3 runs for the transients), and the wall-time ratios (minima) are
given beside them.  Both tools run single-threaded here (OPENBLAS_NUM_THREADS=1, beltjax's
one-thread XLA pool, Exudyn's default of one thread), so on an idle machine CPU time ~ wall time.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import json
import sys
import time
import warnings
from functools import partial
from pathlib import Path

import numpy as np

from _common import (HERE, block, fmt_time, machine_info, machine_line, save_json, table, time_compile,
                     time_first_call, time_interleaved)

FIGURES = HERE / "figures"
REFERENCE = HERE.parents[1] / "shared" / "reference" / "thesis_reference.json"
INSTALL = 'pip install -e ".[benchmark]"'

try:
    import exudyn as exu
    from exudyn.itemInterface import (MarkerNodeCoordinate, MarkerNodePosition, LoadForceVector, NodeGenericODE2,
                                      NodePoint2DSlope1, NodePointGround, ObjectALEANCFCable2D, ObjectANCFCable2D,
                                      ObjectConnectorCoordinate, SensorNode)
except ImportError as _err:  # skip cleanly
    print(f"bench_exudyn: exudyn is not installed ({_err}); skipped.  Install it with {INSTALL}.")
    save_json("exudyn", {"skipped": True, "reason": f"import exudyn failed: {_err}", "install": INSTALL})
    sys.exit(0)

import diffrax  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import scipy.linalg as sl  # noqa: E402
import scipy.optimize as so  # noqa: E402

import beltjax  # noqa: E402
from beltjax import modal, span, transient  # noqa: E402
from beltjax.ancf import Section  # noqa: E402
from beltjax.dynamics import mass_matrix_inverse, span_vector_field  # noqa: E402
from beltjax.integrators import GeneralizedAlpha  # noqa: E402

warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"exudyn.*")
warnings.filterwarnings("ignore", message=r".*deprecated.*")
try:
    exu.config.printToConsole = False  # exudyn >= 1.10
except AttributeError:
    exu.SetWriteToConsole(False)

# --------------------------------------------------------------------------- problem data


def _strip():
    """(L, EA, EI, rhoA) of the thesis strip, from the shared reference file (fallback: its numbers)."""
    try:
        p = json.loads(REFERENCE.read_text())["cantilever_strip"]["properties"]
        return p["L"], p["E"] * p["A"], p["E"] * p["I"], p["rho"] * p["A"]
    except (OSError, KeyError, ValueError):
        return 0.637, 210e9 * 2.25e-5, 210e9 * 4.2188e-12, 7860 * 2.25e-5


L, EA, EI, RHOA = _strip()
MESHES_A = (2, 4, 8, 16, 32)
MODES_A = 4
N_B = 10  # elements of the transient cantilever
F_TIP = -0.2  # N, tip load step (y)
T_END = 1.0  # s
SAVE_DT = 4e-3  # s, output interval
DT_REF = 1e-3 / 128  # s, reference step
DTS_B = (1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5)  # s, settings tried (divide SAVE_DT)
RHOS_B = (1.0, 0.9)
LEVELS_B = (1e-2, 1e-3)  # error levels
EXUDYN_NEWTON_ATOL = 1e-7
N_C = 20
T_C = 100.0  # N
MODES_C = 6
SPEED_FRACTIONS = (0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 0.99)
N_VARIANTS = 1000
SPEED_D = 10.0
EXUDYN_LOOP_BUDGET_S = 40.0  # the full 1000-variant Exudyn loop runs when the first 50 project to less


def exudyn_version() -> str:
    try:
        return exu.GetVersionString()
    except Exception:
        return getattr(exu, "__version__", "unknown")


def _set(obj, new: str, old: str, value):
    """Set a simulation setting by its current name, or the deprecated one on older exudyn."""
    for path in (new, old):
        try:
            o = obj
            parts = path.split(".")
            for p in parts[:-1]:
                o = getattr(o, p)
            setattr(o, parts[-1], value)
            return
        except AttributeError:
            continue
    raise AttributeError(new)


# --------------------------------------------------------------------------- analytic references


def cantilever_analytic_hz(n_modes: int) -> np.ndarray:
    """Euler-Bernoulli cantilever: f_n = (beta_n L)^2 / (2 pi L^2) sqrt(EI/rhoA), cos x cosh x = -1."""
    roots = []
    for n in range(1, n_modes + 1):
        a, b = (n - 1) * np.pi + 0.1, n * np.pi
        roots.append(so.brentq(lambda x: np.cos(x) * np.cosh(x) + 1.0, a, b, xtol=1e-15))
    x = np.array(roots)
    return x**2 / (2 * np.pi * L**2) * np.sqrt(EI / RHOA)


def _moving_beam_det(omega, length, T, EIe, m, c):
    """Scaled determinant of the pinned-pinned boundary conditions of the moving tensioned beam at omega (complex)."""
    b = np.roots([EIe, 0.0, T - m * c * c, -2.0 * m * c * omega, -m * omega**2])
    e = np.exp(1j * b * length)
    s = np.where(np.abs(e) > 1.0, 1.0 / e, 1.0)  # columns that grow along the span are scaled at x = L
    bm = np.max(np.abs(b)) ** 2
    A = np.array([s, s * b**2 / bm, s * e, s * e * b**2 / bm])
    return np.linalg.det(A)


def moving_beam_analytic_hz(guesses_hz, length, T, EIe, m, c):
    """Exact frequencies (Hz) of the pinned-pinned axially moving tensioned beam, refined from guesses (Hz)."""
    out = []
    for f0 in guesses_hz:
        w0 = 2 * np.pi * f0
        try:
            w = so.newton(lambda w: _moving_beam_det(w, length, T, EIe, m, c), complex(w0),
                          x1=complex(w0 * (1 + 1e-6)), tol=1e-14 * w0, maxiter=100)
            out.append(w.real / (2 * np.pi) if abs(w.imag) < 1e-6 * abs(w) else np.nan)
        except RuntimeError:
            out.append(np.nan)
    return np.array(out)


# --------------------------------------------------------------------------- Exudyn models


def exu_cable(n, length, EA_, EI_, m, *, ale_speed=None, ref_strain=0.0):
    """A straight cable of n elements along +x from the origin, no constraints.

    Returns (mbs, SC, node indices, ALE node or None).  With ale_speed, ALE elements
    sharing one NodeGenericODE2 axial-velocity coordinate with that initial velocity.
    """
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    h = length / n
    n_ale = None
    if ale_speed is not None:
        n_ale = mbs.AddNode(NodeGenericODE2(numberOfODE2Coordinates=1, referenceCoordinates=[0.0],
                                            initialCoordinates=[0.0], initialCoordinates_t=[float(ale_speed)]))
    nodes = [mbs.AddNode(NodePoint2DSlope1(referenceCoordinates=[i * h, 0.0, 1.0, 0.0])) for i in range(n + 1)]
    for i in range(n):
        if n_ale is None:
            mbs.AddObject(ObjectANCFCable2D(nodeNumbers=[nodes[i], nodes[i + 1]], length=h, massPerLength=m,
                                            bendingStiffness=EI_, axialStiffness=EA_, referenceAxialStrain=ref_strain))
        else:
            mbs.AddObject(ObjectALEANCFCable2D(nodeNumbers=[nodes[i], nodes[i + 1], n_ale], length=h, massPerLength=m,
                                               bendingStiffness=EI_, axialStiffness=EA_,
                                               referenceAxialStrain=ref_strain))
    return SC, mbs, nodes, n_ale


def exu_cantilever_eigen(n):
    """Exudyn: build, assemble, ComputeODE2Eigenvalues with the clamped coordinates removed; (Hz, vectors)."""
    SC, mbs, nodes, _ = exu_cable(n, L, EA, EI, RHOA)
    mbs.Assemble()
    i0 = mbs.GetNodeODE2Index(nodes[0])
    f, V = mbs.ComputeODE2Eigenvalues(constrainedCoordinates=[i0, i0 + 1, i0 + 2, i0 + 3], convert2Frequencies=True)
    return np.asarray(f), V


def exu_system_matrices(mbs, damping=True):
    """M, K (= -d RHS/dq) and D (= -d RHS/dq_t) of an assembled mbs, the calls ComputeODE2Eigenvalues makes."""
    settings = exu.SimulationSettings()
    _set(settings, "solution.file.write", "solutionSettings.writeSolutionToFile", False)  # no solution/ folder
    solver = exu.MainSolverStatic()
    solver.InitializeSolver(mbs, settings)
    n = solver.GetODE2size()
    solver.ComputeMassMatrix(mbs)
    M = solver.GetSystemMassMatrix()
    solver.ComputeJacobianODE2RHS(mbs, scalarFactor_ODE2=-1, scalarFactor_ODE2_t=0, scalarFactor_ODE1=0)
    K = solver.GetSystemJacobian()[:n, :n]
    D = None
    if damping:
        solver.ComputeJacobianODE2RHS(mbs, scalarFactor_ODE2=0, scalarFactor_ODE2_t=-1, scalarFactor_ODE1=0)
        D = solver.GetSystemJacobian()[:n, :n]
    solver.FinalizeSolver(mbs, settings)
    return M, K, D


def exu_moving_span_matrices(n, T, c):
    """Exudyn ALE span (pinned-pinned, tension T, speed c): reduced M, K, D (ALE and pin coordinates removed)."""
    lam = float(span.stretch_for_tension(T, EA))
    SC, mbs, nodes, n_ale = exu_cable(n, L, EA, EI * lam**3, RHOA / lam, ale_speed=c, ref_strain=-T / EA)
    mbs.Assemble()
    M, K, D = exu_system_matrices(mbs)
    i0, iN = mbs.GetNodeODE2Index(nodes[0]), mbs.GetNodeODE2Index(nodes[-1])
    fixed = [mbs.GetNodeODE2Index(n_ale), i0, i0 + 1, iN, iN + 1]
    keep = np.setdiff1d(np.arange(M.shape[0]), fixed)
    sel = np.ix_(keep, keep)
    return M[sel], K[sel], D[sel]


def exudyn_complex_eigen(M, K, D):
    """ComputeODE2Eigenvalues' complex branch (-inv(A) B, scipy eig), with the reduced sizes; (Hz, vectors).

    Frequencies: the imaginary parts > 0, sorted (one of each conjugate pair).
    """
    n = M.shape[0]
    Z = np.zeros((n, n))
    B = np.block([[K, D], [Z, -M]])
    A = np.block([[Z, M], [M, Z]])
    lam, V = sl.eig(-np.dot(np.linalg.inv(A), B))
    keep = lam.imag > 0
    order = np.argsort(lam.imag[keep])
    return lam.imag[keep][order] / (2 * np.pi), V[:, keep][:, order]


def exu_moving_span_modes(n, T, c):
    """Exudyn (c) route: the complex algorithm with transport; at c = 0 the symmetric one of
    ``ComputeODE2Eigenvalues`` (scipy ``eigh(K, M)``, values and vectors).  (Hz, vectors)."""
    if c == 0.0:
        M, K, _ = exu_moving_span_matrices(n, T, c)
        w2, V = sl.eigh(K, M)
        return np.sqrt(np.abs(w2)) / (2 * np.pi), V
    return exudyn_complex_eigen(*exu_moving_span_matrices(n, T, c))


def exu_moving_span_freqs_only(n, T, c, n_modes):
    """(d): values only, numpy eigvals of the companion matrix."""
    M, K, D = exu_moving_span_matrices(n, T, c)
    m = M.shape[0]
    A = np.block([[np.zeros((m, m)), np.eye(m)], [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
    lam = np.linalg.eigvals(A)
    return np.sort(lam.imag[lam.imag > 0])[:n_modes] / (2 * np.pi)


def exu_cantilever_transient_model(n):
    """Exudyn cantilever for (b): clamped by 4 coordinate constraints, tip load, tip displacement sensor."""
    SC, mbs, nodes, _ = exu_cable(n, L, EA, EI, RHOA)
    n_ground = mbs.AddNode(NodePointGround())
    m_ground = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=n_ground, coordinate=0))
    for k in range(4):
        mk = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=nodes[0], coordinate=k))
        mbs.AddObject(ObjectConnectorCoordinate(markerNumbers=[m_ground, mk]))
    m_tip = mbs.AddMarker(MarkerNodePosition(nodeNumber=nodes[-1]))
    mbs.AddLoad(LoadForceVector(markerNumber=m_tip, loadVector=[0.0, F_TIP, 0.0]))
    sensor = mbs.AddSensor(SensorNode(nodeNumber=nodes[-1], outputVariableType=exu.OutputVariableType.Displacement,
                                      storeInternal=True, writeToFile=False))
    mbs.Assemble()
    return SC, mbs, sensor


def exu_transient(model, dt, rho_inf):
    """Run Exudyn's generalized-alpha over [0, T_END] at the fixed step dt; returns the tip y at the samples."""
    SC, mbs, sensor = model
    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.endTime = T_END
    ti.numberOfSteps = int(round(T_END / dt))
    ti.adaptiveStep = False
    ti.verboseMode = 0
    ti.generalizedAlpha.spectralRadius = float(rho_inf)
    ti.newton.absoluteTolerance = EXUDYN_NEWTON_ATOL
    _set(s, "solution.file.write", "solutionSettings.writeSolutionToFile", False)
    _set(s, "solution.sensors.writePeriod", "solutionSettings.sensorsWritePeriod", SAVE_DT)
    _set(s, "show.statistics", "displayStatistics", False)
    _set(s, "show.computationTime", "displayComputationTime", False)
    ok = mbs.SolveDynamic(s)
    data = np.asarray(mbs.GetSensorStoredData(sensor))
    if not ok:
        raise RuntimeError(f"Exudyn SolveDynamic failed at dt = {dt}, rho_inf = {rho_inf}")
    return data[:, 0], data[:, 2]


# --------------------------------------------------------------------------- beltjax pieces


def bj_cantilever(n):
    return beltjax.analyse_span(L, 0.0, EA, EI, RHOA, n_elements=n, bc=("clamped", "free"))


@partial(jax.jit, static_argnames=("n",))
def bj_cantilever_core(EI_, *, n):
    """One compiled call: span matrices + ``modal.symmetric_modes`` (frequencies Hz, M-orthonormal shapes)."""
    mats = span.span_matrices(Section(EA, EI_, RHOA), L, 0.0, 0.0, n_elements=n, bc=("clamped", "free"))
    omega2, V = modal.symmetric_modes(mats["M"], mats["K"])
    return jnp.sqrt(jnp.clip(omega2, 0.0, None)) / (2 * np.pi), V


def bj_moving(c, n=N_C, T=T_C):
    return beltjax.analyse_span(L, T, EA, EI, RHOA, speed=c, n_elements=n, bc="pinned")


@jax.jit
def bj_pinned_core_at_rest(tension):
    """The jit core at c = 0 (as ``analyse_span`` then does): span matrices + ``modal.symmetric_modes``."""
    mats = span.span_matrices(Section(EA, EI, RHOA), L, tension, 0.0, n_elements=N_C, bc=("pinned", "pinned"))
    omega2, V = modal.symmetric_modes(mats["M"], mats["K"])
    return jnp.all(omega2 > 0), jnp.sqrt(jnp.clip(omega2, 0.0, None)) / (2 * np.pi), V


@jax.jit
def bj_moving_core(c):
    """One compiled call: span matrices + the skew-Hermitian gyroscopic eigen-solve ``analyse_span`` uses
    (``modal._skew_modes``: ok flag, frequencies Hz, complex shapes)."""
    mats = span.span_matrices(Section(EA, EI, RHOA), L, T_C, c, n_elements=N_C, bc=("pinned", "pinned"))
    ok, omega, shapes = modal._skew_modes(mats["M"], mats["G"], mats["K"])
    return ok, omega / (2 * np.pi), shapes


def bj_transient_solver(n=N_B):
    """Jitted (dt, rho_inf) -> (tip y at the samples, result, steps) of the cantilever under the tip load step."""
    bc = ("clamped", "free")
    idx, free = span.element_index(n), span.free_dofs(n, bc)
    L0 = L / n
    q0 = span.straight_state(n, L, 1.0)
    Minv = mass_matrix_inverse(RHOA, L0, idx, free)
    field = span_vector_field(Section(EA, EI, RHOA), L0, idx, free, q0, 0.0, "linear", Minv)
    nf = len(free)
    a_tip = Minv @ jnp.zeros_like(q0).at[4 * n + 1].set(F_TIP)[free]
    load = jnp.concatenate([jnp.zeros(nf), a_tip])

    def f(t, y, args):
        return field(t, y, args) + load

    y0 = jnp.concatenate([q0[free], jnp.zeros(nf)])
    tip = int(np.nonzero(free == 4 * n + 1)[0][0])
    ts = jnp.asarray(SAVE_DT * np.arange(int(round(T_END / SAVE_DT)) + 1))
    max_steps = int(round(T_END / DT_REF)) + 16

    @jax.jit
    def solve(dt, rho_inf):
        solver = GeneralizedAlpha(rho_inf=rho_inf, full_newton=False, jacobian_every=transient.JACOBIAN_EVERY,
                                  newton_iterations=12, rtol=transient.NEWTON_RTOL, atol=transient.NEWTON_ATOL)
        sol = diffrax.diffeqsolve(diffrax.ODETerm(f), solver, 0.0, T_END, dt, y0,
                                  stepsize_controller=diffrax.ConstantStepSize(), saveat=diffrax.SaveAt(ts=ts),
                                  max_steps=max_steps, throw=False)
        return sol.ys[:, tip], sol.result, sol.stats["num_steps"]

    return solve, np.asarray(ts)


def bj_batched_fns():
    """Jitted functions of the tensions: ok flags and first MODES_C frequencies (Hz) of the (c) span at SPEED_D.

    Returns (vmapped, sequential): ``jax.vmap`` over all variants at once, and ``jax.lax.map`` (a compiled
    loop over the variants, one at a time) for comparison.
    """
    sec = Section(EA, EI, RHOA)

    def one(T):
        mats = span.span_matrices(sec, L, T, SPEED_D, n_elements=N_C, bc=("pinned", "pinned"))
        ok, omega = modal.skew_frequencies(mats["M"], mats["G"], mats["K"])
        return ok, omega[:MODES_C] / (2 * np.pi)

    return jax.jit(jax.vmap(one)), jax.jit(lambda Ts: jax.lax.map(one, Ts))


def time_both(fns: dict, rounds: int = 15, min_sample_s: float = 5e-3, max_total_s: float = 3.0) -> dict:
    """Per-call wall and CPU times of zero-argument functions, sampled round-robin after a warm-up call
    (:func:`_common.time_interleaved`).  On the shared 2-core machine the wall time of a sample includes
    the time other processes hold the cores; the CPU time (``time.process_time``: all threads of this
    process, JAX's worker threads included) does not, and is the stable measure of the work done.
    Returns {name: {wall_min_s, wall_median_s, cpu_min_s, cpu_median_s, samples, calls_per_sample}}.
    """
    tm = time_interleaved(fns, rounds=rounds, min_sample_s=min_sample_s, max_total_s=max_total_s)
    return {k: dict(wall_min_s=v["min_s"], wall_median_s=v["median_s"], cpu_min_s=v["cpu_min_s"],
                    cpu_median_s=v["cpu_median_s"], samples=v["samples"], calls_per_sample=v["calls_per_sample"])
            for k, v in tm.items()}


def timed(fn):
    """(result, wall s, CPU s) of one blocked call."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = block(fn())
    return out, time.perf_counter() - w0, time.process_time() - c0


def _cw(st):
    """'CPU median / wall min' of a time_both entry."""
    return f"{fmt_time(st['cpu_median_s'])} / {fmt_time(st['wall_min_s'])}"


def _ratios(tm, a, b):
    """Exudyn-over-beltjax style ratios tm[a] / tm[b]: by CPU median (headline) and by wall minimum."""
    return dict(cpu_median=tm[a]["cpu_median_s"] / tm[b]["cpu_median_s"], wall_min=tm[a]["wall_min_s"] / tm[b]["wall_min_s"],
                wall_median=tm[a]["wall_median_s"] / tm[b]["wall_median_s"])


# --------------------------------------------------------------------------- (a)


def part_a():
    f_an = cantilever_analytic_hz(MODES_A)
    rows, recs = [], []
    for n in MESHES_A:
        jax.clear_caches()
        res, t_first = time_first_call(bj_cantilever, n)
        f_bj = np.asarray(res.frequencies_hz[:MODES_A])
        assert all(lb.endswith("transverse") for lb in res.labels[:MODES_A]), res.labels[:MODES_A]
        core, ct = time_compile(bj_cantilever_core, EI, n=n)
        f_core = np.asarray(core(EI)[0][:MODES_A])
        f_ex = exu_cantilever_eigen(n)[0][:MODES_A]
        tm = time_both({"beltjax": lambda n=n: bj_cantilever(n), "beltjax_core": lambda: core(EI),
                        "exudyn": lambda n=n: exu_cantilever_eigen(n)})
        err_bj, err_ex = (f_bj - f_an) / f_an, (f_ex - f_an) / f_an
        diff = float(max(np.max(np.abs(f_bj - f_ex) / f_an), np.max(np.abs(f_core - f_ex) / f_an)))
        r_api, r_core = _ratios(tm, "exudyn", "beltjax"), _ratios(tm, "exudyn", "beltjax_core")
        rec = dict(n_elements=n, beltjax_hz=f_bj, exudyn_hz=f_ex, rel_err_beltjax=err_bj, rel_err_exudyn=err_ex,
                   max_rel_diff_between_tools=diff, times=tm, beltjax_first_call_s=t_first,
                   beltjax_compile_s=t_first - tm["beltjax"]["wall_min_s"], core_compile=ct,
                   ratio_analyse_span=r_api, ratio_core=r_core)
        recs.append(rec)
        rows.append([n, 4 * n, *[f"{e:+.2e}" for e in err_bj], f"{diff:.0e}",
                     _cw(tm["beltjax"]), _cw(tm["beltjax_core"]), _cw(tm["exudyn"]),
                     f"{r_api['cpu_median']:.2f} / {r_core['cpu_median']:.2f}",
                     f"{r_api['wall_min']:.2f} / {r_core['wall_min']:.2f}",
                     f"{rec['beltjax_compile_s']:.1f} s / {ct['total_s']:.1f} s"])
    t = table(["N", "free coords", *[f"mode {i} rel. err" for i in range(1, MODES_A + 1)],
               "max |beltjax - Exudyn| / f", "beltjax analyse_span", "beltjax jit core", "Exudyn",
               "Exudyn / beltjax, CPU (analyse_span / core)", "same, wall min", "beltjax compile (analyse_span / core)"],
              rows,
              "(a) Cantilever eigen-analysis, first 4 frequencies vs Euler-Bernoulli (" +
              ", ".join(f"{x:.4f}" for x in f_an) + " Hz; the errors are the same in both tools); times per "
              "analysis after compilation: CPU median / wall min of round-robin samples")
    print(t + "\n")
    return dict(analytic_hz=f_an, records=recs, table=t)


# --------------------------------------------------------------------------- (b)


def _err(y, ref):
    return float(np.max(np.abs(np.asarray(y) - ref)) / np.max(np.abs(ref)))


def part_b():
    solve, ts = bj_transient_solver()
    compiled, ct = time_compile(solve, 2.5e-4, 1.0)
    model = exu_cantilever_transient_model(N_B)

    def bj_run(dt, rho):
        y, result, steps = jax.block_until_ready(compiled(dt, rho))
        if not bool(result == diffrax.RESULTS.successful):
            raise RuntimeError(f"beltjax transient failed at dt = {dt}, rho_inf = {rho}")
        return np.asarray(y)

    def ex_run(dt, rho):
        t, y = exu_transient(model, dt, rho)
        assert np.allclose(t, ts, atol=1e-9), "Exudyn sensor times differ from the beltjax samples"
        return y

    # references
    ref_bj, w_ref_bj, c_ref_bj = timed(lambda: bj_run(DT_REF, 1.0))
    ref_ex, w_ref_ex, c_ref_ex = timed(lambda: ex_run(DT_REF, 1.0))
    ref_diff = _err(ref_bj, ref_ex)
    print(f"(b) references (dt = {DT_REF:.3g} s, rho_inf = 1): beltjax {c_ref_bj:.1f} s CPU ({w_ref_bj:.1f} s wall), "
          f"Exudyn {c_ref_ex:.1f} s CPU ({w_ref_ex:.1f} s wall); max |beltjax - Exudyn| / max|y| = {ref_diff:.1e}; "
          f"tip y: min {ref_bj.min() * 1e3:.2f} mm, final {ref_bj[-1] * 1e3:.2f} mm; beltjax compile "
          f"{ct['total_s']:.2f} s\n")

    def attempt(fn):
        """(y, wall s, CPU s, failure message or None); a failed run (Newton, fixed step) is recorded."""
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            y = fn()
            return y, time.perf_counter() - w0, time.process_time() - c0, None
        except Exception as err:  # exudyn.SolverError, or beltjax's RuntimeError
            return None, time.perf_counter() - w0, time.process_time() - c0, f"{type(err).__name__}: {err}"

    runs = []
    for rho in RHOS_B:
        for dt in DTS_B:
            n_steps = int(round(T_END / dt))
            y_bj, w_bj, c_bj, fail_bj = attempt(lambda: bj_run(dt, rho))
            y_ex, w_ex, c_ex, fail_ex = attempt(lambda: ex_run(dt, rho))
            both = y_bj is not None and y_ex is not None
            for tool, y, w, cpu, fail, own, other in (("beltjax", y_bj, w_bj, c_bj, fail_bj, ref_bj, ref_ex),
                                                       ("exudyn", y_ex, w_ex, c_ex, fail_ex, ref_ex, ref_bj)):
                runs.append(dict(tool=tool, rho_inf=rho, dt=dt, steps=n_steps, wall_s=w, cpu_s=cpu, failed=fail,
                                 err=np.inf if y is None else _err(y, own),
                                 err_vs_other_ref=np.inf if y is None else _err(y, other),
                                 same_setting_diff=_err(y_bj, y_ex) if both else None, y=y))

    # cheapest adequate setting (by CPU time) per tool and level, re-timed round-robin: min of 3
    winners = {}
    for level in LEVELS_B:
        for tool in ("beltjax", "exudyn"):
            ok = [r for r in runs if r["tool"] == tool and r["err"] <= level]
            winners[(level, tool)] = min(ok, key=lambda r: r["cpu_s"]) if ok else None
    fns = {}
    for (level, tool), r in winners.items():
        if r is not None:
            key = f"{tool} rho={r['rho_inf']:g} dt={r['dt']:g}"
            fns[key] = ((lambda r=r: bj_run(r["dt"], r["rho_inf"])) if tool == "beltjax"
                        else (lambda r=r: ex_run(r["dt"], r["rho_inf"])))
    retimed = {k: {"wall_s": [], "cpu_s": []} for k in fns}
    for _ in range(3):
        for k, fn in fns.items():
            _, w, cpu = timed(fn)
            retimed[k]["wall_s"].append(w)
            retimed[k]["cpu_s"].append(cpu)

    rows = []
    for r in runs:
        failed = r["failed"] is not None
        rows.append([r["tool"], f"{r['rho_inf']:g}", f"{r['dt']:.3g}", r["steps"],
                     "failed (Newton)" if failed else f"{r['cpu_s']:.3f} s / {r['wall_s']:.3f} s",
                     "-" if failed else f"{1e6 * r['cpu_s'] / r['steps']:.0f} us",
                     "-" if failed else f"{r['err']:.1e}",
                     "-" if r["same_setting_diff"] is None or r["tool"] == "exudyn" else f"{r['same_setting_diff']:.0e}"])
    t_runs = table(["tool", "rho_inf", "dt (s)", "steps", "CPU / wall", "CPU per step", "rel. error vs own ref.",
                    "|beltjax - Exudyn|, same setting"], rows,
                   f"(b) Cantilever ({N_B} el.), tip load step {F_TIP:g} N, {T_END:g} s: every setting tried "
                   f"(one run each; beltjax after compilation)")
    print(t_runs + "\n")
    rows, headline = [], {}
    for level in LEVELS_B:
        wb, we = winners[(level, "beltjax")], winners[(level, "exudyn")]
        cell, best = [], {}
        for tool, w in (("beltjax", wb), ("exudyn", we)):
            if w is None:
                cell.append("none")
                continue
            rt = retimed[f"{tool} rho={w['rho_inf']:g} dt={w['dt']:g}"]
            best[tool] = (min(rt["cpu_s"]), min(rt["wall_s"]))
            cell.append(f"rho_inf {w['rho_inf']:g}, dt {w['dt']:.3g} s, err {w['err']:.1e}: "
                        f"{best[tool][0]:.3f} s / {best[tool][1]:.3f} s")
        both = len(best) == 2
        r_cpu = best["exudyn"][0] / best["beltjax"][0] if both else None
        r_wall = best["exudyn"][1] / best["beltjax"][1] if both else None
        headline[level] = dict(beltjax=None if wb is None else {k: v for k, v in wb.items() if k != "y"},
                               exudyn=None if we is None else {k: v for k, v in we.items() if k != "y"},
                               beltjax_cpu_min_s=best.get("beltjax", (None,))[0],
                               beltjax_wall_min_s=best.get("beltjax", (None, None))[1],
                               exudyn_cpu_min_s=best.get("exudyn", (None,))[0],
                               exudyn_wall_min_s=best.get("exudyn", (None, None))[1],
                               ratio_cpu=r_cpu, ratio_wall=r_wall)
        rows.append([f"{level:g}", *cell, "-" if r_cpu is None else f"{r_cpu:.2f}", "-" if r_wall is None else f"{r_wall:.2f}"])
    t_eq = table(["error level", "beltjax: cheapest setting, CPU / wall (min of 3)",
                  "Exudyn: cheapest setting, CPU / wall (min of 3)", "Exudyn / beltjax, CPU", "same, wall"], rows,
                 f"(b) Equal accuracy: cheapest setting reaching the level (beltjax compile {ct['total_s']:.2f} s "
                 "not included, paid once for every dt and rho_inf)")
    print(t_eq + "\n")
    return dict(compile=ct, reference=dict(dt=DT_REF, beltjax_wall_s=w_ref_bj, beltjax_cpu_s=c_ref_bj,
                                           exudyn_wall_s=w_ref_ex, exudyn_cpu_s=c_ref_ex,
                                           max_rel_diff=ref_diff, ts=ts, y_beltjax=ref_bj, y_exudyn=ref_ex),
                runs=[{k: v for k, v in r.items() if k != "y"} for r in runs], retimed=retimed,
                equal_accuracy={f"{k:g}": v for k, v in headline.items()}, tables={"runs": t_runs, "equal": t_eq},
                _runs_full=runs)


# --------------------------------------------------------------------------- (c)


def part_c():
    lam = float(span.stretch_for_tension(T_C, EA))
    v_crit = float(np.sqrt(T_C * lam / RHOA))
    EIe, me = EI * lam**3, RHOA / lam
    jax.clear_caches()
    _, first_gyro = time_first_call(bj_moving, 10.0)
    core_moving, ct = time_compile(bj_moving_core, 10.0)
    core_rest, ct0 = time_compile(bj_pinned_core_at_rest, T_C)
    rows, recs = [], []
    for frac in SPEED_FRACTIONS:
        c = frac * v_crit
        core = core_moving if c else (lambda c: core_rest(T_C))
        res = bj_moving(c)
        f_bj = np.asarray(res.frequencies_hz[:MODES_C])
        assert all(lb.endswith("transverse") for lb in res.labels[:MODES_C])
        ok, f_core, _ = core(c)
        assert bool(ok)
        f_core = np.asarray(f_core[:MODES_C])
        f_ex = exu_moving_span_modes(N_C, T_C, c)[0][:MODES_C]
        f_an = moving_beam_analytic_hz(f_bj, L, T_C, EIe, me, c)
        tm = time_both({
            "beltjax": lambda c=c: bj_moving(c),
            "beltjax_core": lambda c=c: core(c),
            "exudyn": lambda c=c: exu_moving_span_modes(N_C, T_C, c),
            "exudyn_matrices": lambda c=c: exu_moving_span_matrices(N_C, T_C, c),
        }, max_total_s=4.0)
        e_bj, e_ex = (f_bj - f_an) / f_an, (f_ex - f_an) / f_an
        diff = float(max(np.max(np.abs(f_bj - f_ex) / f_an), np.max(np.abs(f_core - f_ex) / f_an)))
        r_api, r_core = _ratios(tm, "exudyn", "beltjax"), _ratios(tm, "exudyn", "beltjax_core")
        rec = dict(speed_m_s=c, fraction_of_critical=frac, analytic_hz=f_an, beltjax_hz=f_bj, exudyn_hz=f_ex,
                   rel_err_beltjax=e_bj, rel_err_exudyn=e_ex, max_rel_diff_between_tools=diff, times=tm,
                   ratio_analyse_span=r_api, ratio_core=r_core)
        recs.append(rec)
        t_ex, t_exm = tm["exudyn"]["cpu_median_s"], tm["exudyn_matrices"]["cpu_median_s"]
        rows.append([f"{c:.2f} ({frac:g})", f"{f_an[0]:.4f}", f"{e_bj[0]:+.1e}", f"{np.max(np.abs(e_bj)):.1e}",
                     f"{diff:.0e}", _cw(tm["beltjax"]), _cw(tm["beltjax_core"]), _cw(tm["exudyn"]),
                     f"{fmt_time(t_exm)} + {fmt_time(t_ex - t_exm)}",
                     f"{r_api['cpu_median']:.2f} / {r_core['cpu_median']:.2f}",
                     f"{r_api['wall_min']:.2f} / {r_core['wall_min']:.2f}"])
    t = table(["c m/s (c/c_crit)", "f1 exact Hz", "f1 rel. err", "max |err| modes 1-6 (both tools)",
               "max |beltjax - Exudyn| / f", "beltjax analyse_span", "beltjax jit core", "Exudyn",
               "Exudyn: build+M,K,D + eig (CPU)", "Exudyn / beltjax, CPU (analyse_span / core)", "same, wall min"], rows,
              f"(c) Pinned-pinned strip, T = {T_C:g} N, {N_C} elements, transport speed up to 0.99 c_crit "
              f"(c_crit = sqrt(T lam/rhoA) = {v_crit:.3f} m/s); errors vs the exact moving-beam frequencies; "
              f"times CPU median / wall min; beltjax compile: analyse_span cold first call {first_gyro:.2f} s, "
              f"jit core {ct['total_s']:.2f} s (at c = 0: span_matrices + symmetric_modes, {ct0['total_s']:.2f} s)")
    print(t + "\n")
    return dict(stretch=lam, critical_speed_m_s=v_crit, beltjax_first_call_cold_s=first_gyro, core_compile=ct,
                core_compile_at_rest=ct0,
                records=recs, table=t)


# --------------------------------------------------------------------------- (d)


def part_d():
    tensions = np.linspace(50.0, 150.0, N_VARIANTS)
    Tj = jnp.asarray(tensions)
    vmapped, sequential = bj_batched_fns()
    bj = {}
    for name, fn in (("vmap", vmapped), ("lax.map", sequential)):
        compiled, ct = time_compile(fn, Tj)
        walls, cpus = [], []
        for _ in range(2):  # each call is seconds long: min of 2
            (ok, f), w, cpu = timed(lambda: compiled(Tj))
            walls.append(w)
            cpus.append(cpu)
        assert bool(jnp.all(ok))
        bj[name] = dict(compile=ct, walls_s=walls, cpus_s=cpus, wall_min_s=min(walls), cpu_min_s=min(cpus),
                        hz=np.asarray(f))
    f_bj = bj["vmap"]["hz"]
    seq_diff = float(np.max(np.abs(bj["lax.map"]["hz"] - f_bj) / f_bj))

    f_ex, w0, c0 = [], time.perf_counter(), time.process_time()
    n_run = 0
    for T in tensions:
        f_ex.append(exu_moving_span_freqs_only(N_C, T, SPEED_D, MODES_C))
        n_run += 1
        if n_run == 50 and (time.perf_counter() - w0) * N_VARIANTS / 50 > EXUDYN_LOOP_BUDGET_S:
            break
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    f_ex = np.array(f_ex)
    ex_wall_1000, ex_cpu_1000 = wall * N_VARIANTS / n_run, cpu * N_VARIANTS / n_run
    extrapolated = n_run < N_VARIANTS
    diff = float(np.max(np.abs(f_ex - f_bj[:n_run]) / f_bj[:n_run]))
    err = []  # exact reference for 5 variants
    for i in np.linspace(0, N_VARIANTS - 1, 5).astype(int):
        lam = float(span.stretch_for_tension(tensions[i], EA))
        fa = moving_beam_analytic_hz(f_bj[i], L, tensions[i], EI * lam**3, RHOA / lam, SPEED_D)
        err.append(float(np.max(np.abs(f_bj[i] - fa) / fa)))
    rows = []
    for name, label in (("vmap", "beltjax: jit(vmap(span_matrices + skew_frequencies)), one call"),
                        ("lax.map", "beltjax: jit(lax.map(same)), one call, variants in a compiled loop")):
        r = bj[name]
        rows.append([label, f"{fmt_time(r['cpu_min_s'])} / {fmt_time(r['wall_min_s'])}",
                     fmt_time(r["cpu_min_s"] / N_VARIANTS), f"{r['compile']['total_s']:.1f} s",
                     f"{ex_cpu_1000 / r['cpu_min_s']:.2f}", f"{ex_wall_1000 / r['wall_min_s']:.2f}"])
    rows.append([f"Exudyn: Python loop, rebuild + M,K,D + numpy eigvals ({n_run} variants run"
                 + (", times extrapolated linearly to 1000)" if extrapolated else ")"),
                 f"{fmt_time(ex_cpu_1000)} / {fmt_time(ex_wall_1000)}", fmt_time(ex_cpu_1000 / N_VARIANTS), "-", "-", "-"])
    t = table(["route", f"{N_VARIANTS} variants, CPU / wall (beltjax: min of 2)", "CPU per variant", "compile",
               "Exudyn / this route, CPU", "same, wall"], rows,
              f"(d) {N_VARIANTS} tension variants (T = 50..150 N) of the {N_C}-element strip at c = {SPEED_D:g} m/s, "
              f"first {MODES_C} frequencies (values only); max |beltjax - Exudyn| / f = {diff:.0e} over {n_run} "
              f"variants; beltjax max rel. error vs the exact beam (5 variants) {max(err):.1e}")
    print(t + "\n")
    return dict(tensions=[float(tensions[0]), float(tensions[-1]), N_VARIANTS],
                beltjax={k: {kk: vv for kk, vv in v.items() if kk != "hz"} for k, v in bj.items()},
                beltjax_vmap_vs_laxmap_max_rel_diff=seq_diff,
                exudyn_variants_run=n_run, exudyn_wall_s=wall, exudyn_cpu_s=cpu,
                exudyn_1000_wall_s=ex_wall_1000, exudyn_1000_cpu_s=ex_cpu_1000, exudyn_extrapolated=extrapolated,
                max_rel_diff_between_tools=diff, beltjax_max_rel_err_vs_exact=max(err),
                ratio_vmap=dict(cpu=ex_cpu_1000 / bj["vmap"]["cpu_min_s"], wall=ex_wall_1000 / bj["vmap"]["wall_min_s"]),
                ratio_laxmap=dict(cpu=ex_cpu_1000 / bj["lax.map"]["cpu_min_s"],
                                  wall=ex_wall_1000 / bj["lax.map"]["wall_min_s"]), table=t)


# --------------------------------------------------------------------------- figure


def figure(a, b, c):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker  # noqa: F401

    FIGURES.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(2, 2, figsize=(12, 8.5))
    # (a)
    ns = [r["n_elements"] for r in a["records"]]
    for key, mk, lab in (("beltjax", "o-", "beltjax analyse_span"), ("beltjax_core", "^-", "beltjax jit core"),
                         ("exudyn", "s--", "Exudyn build + eigen")):
        ax[0, 0].loglog(ns, [r["times"][key]["cpu_median_s"] * 1e3 for r in a["records"]], mk, label=lab)
    ax2 = ax[0, 0].twinx()
    ax2.loglog(ns, [np.max(np.abs(r["rel_err_beltjax"])) for r in a["records"]], "k:", marker="x",
               label="max rel. error, modes 1-4 (both)")
    ax2.set_ylabel("max rel. frequency error (both tools)")
    ax[0, 0].set_xticks(ns)
    ax[0, 0].set_xticklabels([str(n) for n in ns])
    ax[0, 0].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax[0, 0].set_xlabel("elements")
    ax[0, 0].set_ylabel("CPU time per eigen-analysis, median (ms)")
    ax[0, 0].set_title("(a) cantilever eigen-analysis")
    h1, l1 = ax[0, 0].get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax[0, 0].legend(h1 + h2, l1 + l2, fontsize=8, loc="upper left")
    # (b) work-precision
    for tool, mk in (("beltjax", "o"), ("exudyn", "s")):
        for rho, ls in zip(RHOS_B, ("-", "--")):
            rr = [r for r in b["_runs_full"] if r["tool"] == tool and r["rho_inf"] == rho and r["failed"] is None]
            ax[0, 1].loglog([r["cpu_s"] for r in rr], [r["err"] for r in rr], marker=mk, ls=ls,
                            label=f"{'Exudyn' if tool == 'exudyn' else 'beltjax'}, rho_inf = {rho:g}")
    for level in LEVELS_B:
        ax[0, 1].axhline(level, color="grey", lw=0.7)
    ax[0, 1].set_xlabel("CPU time for 1 s simulated (s)")
    ax[0, 1].set_ylabel("max rel. tip error")
    ax[0, 1].set_title(f"(b) work-precision, cantilever {N_B} el., tip load step")
    ax[0, 1].legend(fontsize=8)
    # (b) trace
    ref = b["reference"]
    ax[1, 0].plot(ref["ts"], 1e3 * ref["y_beltjax"], label="beltjax reference")
    ax[1, 0].plot(ref["ts"], 1e3 * ref["y_exudyn"], "--", label="Exudyn reference")
    ax[1, 0].set_xlabel("t (s)")
    ax[1, 0].set_ylabel("tip y displacement (mm)")
    ax[1, 0].set_title(f"(b) reference runs, dt = {DT_REF:.3g} s (max diff {ref['max_rel_diff']:.0e})")
    ax[1, 0].legend(fontsize=8)
    # (c)
    cs = np.array([r["speed_m_s"] for r in c["records"]])
    for k in range(MODES_C):
        ax[1, 1].plot(cs, [r["analytic_hz"][k] for r in c["records"]], "k-", lw=0.8,
                      label="exact moving beam" if k == 0 else None)
        ax[1, 1].plot(cs, [r["beltjax_hz"][k] for r in c["records"]], "o", mfc="none", color="C0",
                      label="beltjax" if k == 0 else None)
        ax[1, 1].plot(cs, [r["exudyn_hz"][k] for r in c["records"]], "x", color="C1",
                      label="Exudyn ALE cable" if k == 0 else None)
    ax[1, 1].axvline(c["critical_speed_m_s"], color="grey", lw=0.7)
    ax[1, 1].set_xlabel("transport speed c (m/s)")
    ax[1, 1].set_ylabel("frequency (Hz)")
    ax[1, 1].set_title(f"(c) pinned-pinned strip, T = {T_C:g} N, {N_C} el.")
    ax[1, 1].legend(fontsize=8)
    fig.tight_layout()
    path = FIGURES / "exudyn_comparison.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------- main


def thread_affinity() -> dict:
    """CPU affinity of this process's threads: {cpu list: number of threads} (Linux; empty elsewhere).

    Recorded because it shapes beltjax's wall times: beltjax pins the main thread to one core while
    JAX creates its CPU client (to get a one-thread XLA pool) and then restores the main thread's
    mask only, so the XLA worker threads stay on that one core; on a busy machine beltjax's
    jitted code then queues for that core while Exudyn (main thread) can use either.
    """
    out = {}
    for task in Path("/proc/self/task").glob("*"):
        try:
            line = next(ln for ln in (task / "status").read_text().splitlines() if ln.startswith("Cpus_allowed_list"))
        except (OSError, StopIteration):
            continue
        cpus = line.split()[-1]
        out[cpus] = out.get(cpus, 0) + 1
    return out



def main():
    t_start, c_start = time.perf_counter(), time.process_time()
    info = machine_info()
    print(f"Machine: {machine_line(info)}; exudyn {exudyn_version()}\n")
    print(f"Strip: L = {L} m, EA = {EA:.6g} N, EI = {EI:.6g} N m^2, rhoA = {RHOA:.6g} kg/m\n")
    block(jnp.ones(2) + 1.0)  # start JAX's CPU client and its threads
    affinity = thread_affinity()
    print(f"Thread CPU affinity of this process {{cpus: threads}}: {affinity}\n")
    a = part_a()
    b = part_b()
    c = part_c()
    d = part_d()
    path = figure(a, b, c)
    elapsed = time.perf_counter() - t_start
    cpu_share = (time.process_time() - c_start) / elapsed
    eq = b["equal_accuracy"]
    summary = {
        "exudyn_version": exudyn_version(),
        "ratio_definition": "Exudyn time / beltjax time (> 1: beltjax faster), by process CPU time (headline: the "
                            "shared machine's load inflates wall times) and by wall time; eigen-analyses: CPU "
                            "median and wall minimum of round-robin samples; transient: min of 3 runs; batched: "
                            "min of 2 beltjax calls vs one Exudyn loop",
        "a_cantilever_ratio_cpu_analyse_span": {str(r["n_elements"]): r["ratio_analyse_span"]["cpu_median"]
                                                for r in a["records"]},
        "a_cantilever_ratio_cpu_jit_core": {str(r["n_elements"]): r["ratio_core"]["cpu_median"] for r in a["records"]},
        "a_cantilever_ratio_wall_analyse_span": {str(r["n_elements"]): r["ratio_analyse_span"]["wall_min"]
                                                 for r in a["records"]},
        "a_cantilever_ratio_wall_jit_core": {str(r["n_elements"]): r["ratio_core"]["wall_min"] for r in a["records"]},
        "a_max_rel_diff_between_tools": max(r["max_rel_diff_between_tools"] for r in a["records"]),
        "b_transient_ratio_cpu_at_1e-2": eq["0.01"]["ratio_cpu"],
        "b_transient_ratio_cpu_at_1e-3": eq["0.001"]["ratio_cpu"],
        "b_transient_ratio_wall_at_1e-2": eq["0.01"]["ratio_wall"],
        "b_transient_ratio_wall_at_1e-3": eq["0.001"]["ratio_wall"],
        "b_beltjax_compile_s": b["compile"]["total_s"],
        "b_reference_max_rel_diff_between_tools": b["reference"]["max_rel_diff"],
        "c_moving_span_ratio_cpu_analyse_span": {f"{r['speed_m_s']:.2f}": r["ratio_analyse_span"]["cpu_median"]
                                                 for r in c["records"]},
        "c_moving_span_ratio_cpu_jit_core": {f"{r['speed_m_s']:.2f}": r["ratio_core"]["cpu_median"]
                                             for r in c["records"]},
        "c_max_rel_diff_between_tools": max(r["max_rel_diff_between_tools"] for r in c["records"]),
        "d_batched_ratio_vmap": d["ratio_vmap"],
        "d_batched_ratio_laxmap": d["ratio_laxmap"],
        "d_exudyn_extrapolated": d["exudyn_extrapolated"],
        "load_avg_at_start": info["loadavg_1_5_15min"],
        "cpu_share_of_one_core": cpu_share,
        "thread_affinity": affinity,
        "elapsed_s": elapsed,
    }
    print("Summary (ratios are Exudyn time / beltjax time, > 1: beltjax faster):")
    for k, v in summary.items():
        print(f"  {k}: {v}")
    print(f"\nFigure {path}\nTotal benchmark time {elapsed:.1f} s (this process got {cpu_share:.2f} of a core on "
          f"average; load average at the start {info['loadavg_1_5_15min'][0]:.2f})")
    b = {k: v for k, v in b.items() if not k.startswith("_")}
    out = save_json("exudyn", {
        "skipped": False, "exudyn_version": exudyn_version(),
        "strip": dict(length=L, EA=EA, EI=EI, rhoA=RHOA),
        "settings": dict(meshes_a=MESHES_A, n_b=N_B, tip_load_N=F_TIP, t_end_s=T_END, save_dt_s=SAVE_DT, dt_ref_s=DT_REF,
                         dts_b=DTS_B, rhos_b=RHOS_B, levels_b=LEVELS_B, exudyn_newton_atol=EXUDYN_NEWTON_ATOL,
                         n_c=N_C, tension_c=T_C, speed_fractions=SPEED_FRACTIONS, n_variants=N_VARIANTS,
                         speed_d=SPEED_D),
        "summary": summary, "a": a, "b": b, "c": c, "d": d, "figure": str(path.relative_to(HERE)), "elapsed_s": elapsed,
    })
    print(f"Saved {out}")


if __name__ == "__main__":
    main()
