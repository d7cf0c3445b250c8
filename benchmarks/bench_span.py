"""Span eigen-analysis: timing split, eigen-solver alternatives, accuracy vs mesh.

Run: ``python benchmarks/bench_span.py``; writes ``benchmarks/results/bench_span.json``.

(a) 20-element pinned-pinned thesis steel strip (L = 0.637 m, T = 100 N) at
    c = 10 m/s (gyroscopic) and c = 0 (symmetric): matrix build
    (``span.span_matrices``, jitted), eigen-solve (``modal.gyroscopic_eigen`` /
    ``modal.symmetric_modes`` as ``analyse_span`` calls them, eagerly), the rest
    of ``analyse_span`` and the whole call.  Target of the brief: < 10 ms with
    transport (Exudyn + scipy reference: 8-12 ms).
    Gyroscopic eigen-solver alternatives, all on the same M, G, K, checked
    against the current route (frequencies to 1e-8 relative) and by the
    backward error of each eigenpair:

      companion  [[0, I], [-M^-1 K, -M^-1 G]] with jnp.linalg.eig (eig fallback) or numpy.linalg.eig
      pencil     A = [[0, I], [-K, -G]], B = [[I, 0], [0, M]] with scipy.linalg.eig (QZ)
      skew       K > 0: B = diag(K, M) = L L^T, A = [[0, K], [-K, -G]] is skew; S = L^-1 A L^-T
                 = [[0, Lk^T Lm^-T], [-Lm^-1 Lk, -Lm^-1 G Lm^-T]] is real skew-symmetric, i S is
                 Hermitian: lambda = -i mu with mu from eigh(i S); x = Lk^-T w[:n].
                 Valid below the critical speed (K positive definite; Cholesky fails otherwise).

(b) Accuracy vs elements: pinned-pinned spans at c = 0, first 8 transverse
    frequencies against f_n = n/(2L) sqrt((T + EI (n pi/L)^2)/rhoA), time per
    analysis (after compilation) and cold compile time (first call after
    ``jax.clear_caches()`` minus steady state) per mesh; thesis strip and the
    bench belt span.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import time

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
import scipy.linalg as sl

import beltjax
from _common import (fmt_time, machine_info, machine_line, save_json, table, time_compile, time_first_call,
                     time_interleaved, time_steady)
from beltjax import modal, span
from beltjax.ancf import Section

STRIP = dict(length=0.637, EA=210e9 * 2.25e-5, EI=210e9 * 4.2188e-12, rhoA=7860 * 2.25e-5, tension=100.0)
BELT = dict(length=0.67143, EA=111190.0, EI=0.034, rhoA=0.12166, tension=100.5)
SPEED = 10.0
N_A = 20
MESHES = (2, 4, 6, 8, 12, 16, 20, 32)
N_MODES = 8
TARGET_S = 10e-3
AGREE_RTOL = 1e-8


# --------------------------------------------------------------------------- eigen-solver routes
# each returns (lam, X): eigenvalues (1/s) and displacement parts of the eigenvectors (columns)


def route_jnp_companion_eager(M, G, K):
    return modal.gyroscopic_eigen(M, G, K)


route_jnp_companion_jit = jax.jit(modal.gyroscopic_eigen)


def route_np_companion(M, G, K):
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, G)]])
    lam, Z = np.linalg.eig(A)
    return lam, Z[:n]


def route_scipy_pencil(M, G, K):
    n = M.shape[0]
    Z0, I = np.zeros((n, n)), np.eye(n)
    A = np.block([[Z0, I], [-K, -G]])
    B = np.block([[I, Z0], [Z0, M]])
    lam, Z = sl.eig(A, B)
    return lam, Z[:n]


def _skew_np(M, G, K):
    """Real skew-symmetric S and the Cholesky factor of K (numpy / scipy)."""
    n = M.shape[0]
    Lk = np.linalg.cholesky(K)
    Lm = np.linalg.cholesky(M)
    C = sl.solve_triangular(Lm, Lk, lower=True).T  # Lk^T Lm^-T
    D = sl.solve_triangular(Lm, sl.solve_triangular(Lm, G, lower=True).T, lower=True).T  # Lm^-1 G Lm^-T
    S = np.block([[np.zeros((n, n)), C], [-C.T, -D]])
    return S, Lk


def _skew_vectors(mu, W, Lk):
    n = Lk.shape[0]
    return -1j * mu, sl.solve_triangular(Lk.T, W[:n], lower=False)


def route_skew_scipy(M, G, K):
    S, Lk = _skew_np(M, G, K)
    mu, W = sl.eigh(1j * S, driver="evd")
    return _skew_vectors(mu, W, Lk)


def route_skew_numpy(M, G, K):
    S, Lk = _skew_np(M, G, K)
    mu, W = np.linalg.eigh(1j * S)
    return _skew_vectors(mu, W, Lk)


def route_skew_scipy_half(M, G, K):
    """Only the n eigenpairs with positive imaginary part (mu < 0): one of each conjugate pair."""
    S, Lk = _skew_np(M, G, K)
    n = M.shape[0]
    mu, W = sl.eigh(1j * S, subset_by_index=[0, n - 1], driver="evr")
    return _skew_vectors(mu, W, Lk)


@jax.jit
def route_skew_jax(M, G, K):
    n = M.shape[0]
    Lk = jnp.linalg.cholesky(K)
    Lm = jnp.linalg.cholesky(M)
    C = jsl.solve_triangular(Lm, Lk, lower=True).T
    D = jsl.solve_triangular(Lm, jsl.solve_triangular(Lm, G, lower=True).T, lower=True).T
    S = jnp.block([[jnp.zeros((n, n)), C], [-C.T, -D]])
    mu, W = jnp.linalg.eigh(1j * S)
    return -1j * mu, jsl.solve_triangular(Lk.T, W[:n], lower=False)


def route_skew_values_only(M, G, K):
    S, _ = _skew_np(M, G, K)
    mu = sl.eigh(1j * S, eigvals_only=True, driver="evd")
    return -1j * mu, None


def route_skew_squared_values_only(M, G, K):
    """-S^2 = S^T S is real symmetric with eigenvalues omega^2 (each twice): real eigh, values only."""
    S, _ = _skew_np(M, G, K)
    w2 = np.linalg.eigvalsh(S.T @ S)
    w = np.sqrt(np.clip(w2[::2], 0.0, None))
    return np.concatenate([1j * w, -1j * w]), None


GYRO_ROUTES = {
    "jnp.linalg.eig companion, eager (eig fallback)": (route_jnp_companion_eager, "jax"),
    "jnp.linalg.eig companion, jit": (route_jnp_companion_jit, "jax"),
    "numpy.linalg.eig companion": (route_np_companion, "np"),
    "scipy.linalg.eig pencil (QZ)": (route_scipy_pencil, "np"),
    "skew: scipy eigh(iS) evd": (route_skew_scipy, "np"),
    "skew: numpy eigh(iS)": (route_skew_numpy, "np"),
    "skew: jnp eigh(iS), jit": (route_skew_jax, "jax"),
    "skew: scipy eigh(iS) half (evr)": (route_skew_scipy_half, "np"),
    "skew: scipy eigvalsh(iS), values only": (route_skew_values_only, "np"),
    "skew: real eigvalsh(S^T S), values only": (route_skew_squared_values_only, "np"),
}


def positive_frequencies(lam):
    """Sorted imaginary parts (rad/s) of the eigenvalues with positive imaginary part."""
    lam = np.asarray(lam)
    return np.sort(lam.imag[lam.imag > 0])


def backward_error(lam, X, M, G, K):
    """Max over eigenpairs (positive imaginary part) of ||(l^2 M + l G + K) x|| / ((|l|^2|M| + |l||G| + |K|)|x|)."""
    if X is None:
        return None
    lam, X = np.asarray(lam), np.asarray(X)
    nM, nG, nK = (np.linalg.norm(A, 2) for A in (M, G, K))
    keep = lam.imag > 0
    lam, X = lam[keep], X[:, keep]
    R = M @ X * lam**2 + G @ X * lam + K @ X
    denom = (np.abs(lam) ** 2 * nM + np.abs(lam) * nG + nK) * np.linalg.norm(X, axis=0)
    return float(np.max(np.linalg.norm(R, axis=0) / denom))


# --------------------------------------------------------------------------- (a)


def part_a():
    sec = Section(STRIP["EA"], STRIP["EI"], STRIP["rhoA"])
    L, T = STRIP["length"], STRIP["tension"]
    kw = dict(n_elements=N_A, bc=("pinned", "pinned"), bending="linear")
    out = {}

    # matrix build: compile (lower + compile), then steady state of the jitted function
    _, ct = time_compile(span.span_matrices, sec, L, T, SPEED, **kw)
    out["span_matrices_compile"] = ct

    def analyse(speed):
        return beltjax.analyse_span(L, T, STRIP["EA"], STRIP["EI"], STRIP["rhoA"], speed=speed, n_elements=N_A, bc="pinned")

    rows, split = [], {}
    free = span.free_dofs(N_A, ("pinned", "pinned"))
    n_coords = 4 * (N_A + 1)
    for speed in (SPEED, 0.0):
        jax.clear_caches()  # cold first call: compiles span_matrices and the eager eigen-solve ops
        _, t_first = time_first_call(analyse, speed)
        mats = span.span_matrices(sec, L, T, speed, **kw)
        M, G, K = mats["M"], mats["G"], mats["K"]
        if speed:
            def eigen():
                return modal.gyroscopic_modes(M, G, K)
            V = eigen()[2]
        else:
            def eigen():
                return modal.symmetric_modes(M, K)
            V = np.asarray(eigen()[1])
        Mnp = np.asarray(M)
        fns = {
            "build": lambda: span.span_matrices(sec, L, T, speed, **kw),
            "eigen": eigen,
            "labels": lambda: span._label_modes(V, Mnp, free),
            "analyse": lambda: analyse(speed),
        }
        tm = time_interleaved(fns, rounds=31)
        t_build, t_eig, t_lab, t_all = (tm[k]["median_s"] for k in ("build", "eigen", "labels", "analyse"))
        other = t_all - t_build - t_eig - t_lab
        key = f"c={speed:g}"
        split[key] = dict(times=tm, other_s=other, analyse_span_first_call_s=t_first)
        eig_name = "gyroscopic_modes, skew route" if speed else "symmetric_modes, jnp eigh"
        ratio = TARGET_S / t_all
        rows.append([f"{speed:g} m/s", fmt_time(t_build), f"{fmt_time(t_eig)} ({eig_name})", fmt_time(t_lab),
                     fmt_time(other), fmt_time(t_all), fmt_time(t_first),
                     f"{ratio:.2f}x ({'met' if ratio > 1 else 'NOT met'})"])
    out["split"] = split
    n_free = int(mats["M"].shape[0])
    t_split = table(
        ["speed c", "span_matrices (jit)", "eigen-solve (eager)", "_label_modes", "other", "analyse_span",
         "first call (cold)", "10 ms target / time"],
        rows, f"(a) Thesis strip, {N_A} pinned-pinned elements ({n_free} free coordinates); "
              f"span_matrices compile {ct['total_s']:.2f} s (trace+lower {ct['lower_s']:.2f} s)")
    print(t_split + "\n")

    # gyroscopic eigen-solver alternatives on the c = 10 m/s matrices
    mats = span.span_matrices(sec, L, T, SPEED, **kw)
    Mj, Gj, Kj = mats["M"], mats["G"], mats["K"]
    M, G, K = (np.asarray(a) for a in (Mj, Gj, Kj))
    ref = positive_frequencies(route_jnp_companion_eager(Mj, Gj, Kj)[0])
    routes, rows, calls = {}, [], {}
    for name, (fn, kind) in GYRO_ROUTES.items():
        args = (Mj, Gj, Kj) if kind == "jax" else (M, G, K)
        compile_s = None
        if name.endswith(", jit"):
            _, compile_s = time_first_call(fn, *args)
        calls[name] = (lambda fn=fn, args=args: fn(*args))
        lam, X = fn(*args)
        f = positive_frequencies(lam)
        if f.shape == ref.shape:
            rel = np.abs(f - ref) / ref
            max_rel, rel_low = float(np.max(rel)), float(np.max(rel[:10]))
        else:
            max_rel = rel_low = float("nan")
        be = backward_error(lam, X, M, G, K)
        max_real = float(np.max(np.abs(np.asarray(lam).real)) / np.max(np.abs(np.asarray(lam))))
        routes[name] = dict(compile_first_call_s=compile_s, max_rel_diff_vs_current=max_rel,
                            max_rel_diff_lowest10=rel_low, backward_error=be, max_rel_real_part=max_real,
                            agrees_1e8=bool(max_rel <= AGREE_RTOL), vectors=X is not None)
    times = time_interleaved(calls, rounds=41, max_total_s=8.0)
    for name in routes:
        routes[name]["time"] = times[name]
    t_cur = routes["jnp.linalg.eig companion, eager (eig fallback)"]["time"]["median_s"]
    for name, r in routes.items():
        rows.append([name, fmt_time(r["time"]["median_s"]), f"{t_cur / r['time']['median_s']:.2f}x",
                     "yes" if r["vectors"] else "no", f"{r['max_rel_diff_vs_current']:.1e}",
                     f"{r['max_rel_diff_lowest10']:.1e}", "-" if r["backward_error"] is None else f"{r['backward_error']:.1e}",
                     f"{r['max_rel_real_part']:.0e}",
                     "-" if r["compile_first_call_s"] is None else f"{r['compile_first_call_s']:.2f} s"])
    t_gyro = table(
        ["route", "median", "speed-up vs eig fallback", "vectors", "max rel. freq diff vs eig (all 80)",
         "(lowest 10)", "backward error", "max |Re l|/|l|", "jit first call"],
        rows, f"(a) Gyroscopic eigen-solve alternatives, c = {SPEED:g} m/s, n = {n_free} (2n = {2 * n_free})")
    print(t_gyro + "\n")
    eligible = {k: v for k, v in routes.items() if v["vectors"] and v["agrees_1e8"]}
    fastest = min(eligible, key=lambda k: eligible[k]["time"]["median_s"])
    out["gyro_routes"] = routes
    out["fastest_route_with_vectors_agreeing"] = fastest
    out["fastest_speedup_vs_current"] = t_cur / routes[fastest]["time"]["median_s"]
    print(f"Fastest route with eigenvectors and frequencies within {AGREE_RTOL:g} of the current one: {fastest} "
          f"({fmt_time(routes[fastest]['time']['median_s'])}, {out['fastest_speedup_vs_current']:.2f}x faster than "
          f"{fmt_time(t_cur)})\n")

    # symmetric (c = 0) alternatives, for completeness
    mats0 = span.span_matrices(sec, L, T, 0.0, **kw)
    M0, K0 = np.asarray(mats0["M"]), np.asarray(mats0["K"])
    sym_jit = jax.jit(modal.symmetric_modes)
    _, sym_compile = time_first_call(sym_jit, mats0["M"], mats0["K"])
    w_ref = np.asarray(modal.symmetric_modes(mats0["M"], mats0["K"])[0])
    sym = {
        "symmetric_modes, eager (eig fallback)": (lambda: modal.symmetric_modes(mats0["M"], mats0["K"]), None),
        "symmetric_modes, jit": (lambda: sym_jit(mats0["M"], mats0["K"]), sym_compile),
        "scipy.linalg.eigh(K, M)": (lambda: sl.eigh(K0, M0), None),
        "scipy.linalg.eigh(K, M) values only": (lambda: (sl.eigh(K0, M0, eigvals_only=True), None), None),
    }
    rows, sym_out = [], {}
    t0 = None
    for name, (fn, comp) in sym.items():
        tm = time_steady(fn)
        w = np.asarray(fn()[0])
        rel = float(np.max(np.abs(np.sqrt(w) - np.sqrt(w_ref)) / np.sqrt(w_ref)))
        t0 = t0 or tm["median_s"]
        sym_out[name] = dict(time=tm, max_rel_freq_diff=rel)
        rows.append([name, fmt_time(tm["median_s"]), f"{t0 / tm['median_s']:.2f}x", f"{rel:.1e}"])
    t_sym = table(["route", "median", "speed-up vs eig fallback", "max rel. freq diff"], rows,
                  f"(a) Symmetric eigen-solve alternatives, c = 0, n = {n_free}")
    print(t_sym + "\n")
    out["sym_routes"] = sym_out
    out["tables"] = {"split": t_split, "gyro": t_gyro, "sym": t_sym}
    return out


# --------------------------------------------------------------------------- (b)


def analytic(p, n_modes, stretch=None):
    """f_n = n/(2L) sqrt((T + EI (n pi/L)^2)/rhoA); with ``stretch`` lam: rhoA/lam and EI lam^3 (stretched span)."""
    n = np.arange(1, n_modes + 1)
    L, T, EI, rhoA = p["length"], p["tension"], p["EI"], p["rhoA"]
    if stretch is not None:
        EI, rhoA = EI * stretch**3, rhoA / stretch
    return n / (2 * L) * np.sqrt((T + EI * (n * np.pi / L) ** 2) / rhoA)


def part_b():
    out, tables = {}, {}
    for label, p in (("thesis strip", STRIP), ("bench belt span", BELT)):
        f_an = analytic(p, N_MODES)
        rows, recs = [], []
        for N in MESHES:
            def call():
                return beltjax.analyse_span(p["length"], p["tension"], p["EA"], p["EI"], p["rhoA"], speed=0.0,
                                            n_elements=N, bc="pinned")

            jax.clear_caches()
            res, t_first = time_first_call(call)
            tm = time_steady(call, max_total_s=1.0)
            f = np.array([fr for fr, lb in zip(res.frequencies_hz, res.labels) if "transverse" in lb][:N_MODES])
            err = np.full(N_MODES, np.nan)
            err[: len(f)] = (f - f_an[: len(f)]) / f_an[: len(f)]
            f_st = analytic(p, N_MODES, res.stretch)
            err_st = np.full(N_MODES, np.nan)
            err_st[: len(f)] = (f - f_st[: len(f)]) / f_st[: len(f)]
            max_err = float(np.nanmax(np.abs(err)))
            rec = dict(n_elements=N, n_transverse_found=len(f), frequencies_hz=f, rel_error=err,
                       max_abs_rel_error=max_err, rel_error_stretch_corrected=err_st,
                       max_abs_rel_error_stretch_corrected=float(np.nanmax(np.abs(err_st))),
                       time=tm, first_call_s=t_first, compile_s=t_first - tm["median_s"], stretch=res.stretch)
            recs.append(rec)
            rows.append([N, *[("-" if np.isnan(e) else f"{100 * e:+.2e}") for e in err], f"{100 * max_err:.2e}",
                         f"{100 * err_st[0]:+.2e}", f"{100 * rec['max_abs_rel_error_stretch_corrected']:.2e}", fmt_time(tm["median_s"]),
                         f"{rec['compile_s']:.2f} s"])
        lam = recs[-1]["stretch"]
        title = (f"(b) {label}: L={p['length']}, T={p['tension']}, EA={p['EA']:.6g}, EI={p['EI']:.6g}, "
                 f"rhoA={p['rhoA']:.6g}, c=0; relative error (%) of the transverse frequencies vs "
                 f"f_n = n/(2L) sqrt((T + EI (n pi/L)^2)/rhoA); analytic f1..f8 = "
                 + ", ".join(f"{x:.2f}" for x in f_an) + f" Hz; stretch lam = {lam:.6f}")
        t = table(["N", *[f"mode {i}" for i in range(1, N_MODES + 1)], "max |err| %",
                   "mode 1, stretch-corr.", "max |err| %, stretch-corr.", "time/analysis", "compile"], rows, title)
        print(t + "\n")
        out[label] = dict(params=p, analytic_hz=f_an, records=recs)
        tables[label] = t
    out["tables"] = tables
    return out


def main():
    t_start = time.perf_counter()
    info = machine_info()
    print(f"Machine: {machine_line(info)}\n")
    a = part_a()
    b = part_b()
    elapsed = time.perf_counter() - t_start
    t_gyro = a["split"][f"c={SPEED:g}"]["times"]["analyse"]["median_s"]
    t_sym = a["split"]["c=0"]["times"]["analyse"]["median_s"]
    summary = {
        "analyse_span 20 el. c=10 (ms)": 1e3 * t_gyro,
        "target 10 ms met": t_gyro < TARGET_S,
        "target / time": TARGET_S / t_gyro,
        "fastest gyroscopic route": a["fastest_route_with_vectors_agreeing"],
        "fastest route speed-up vs eig fallback": a["fastest_speedup_vs_current"],
        "analyse_span 20 el. c=0 (ms)": 1e3 * t_sym,
    }
    for k, v in summary.items():
        print(f"{k}: {v}")
    print(f"\nTotal benchmark time {elapsed:.1f} s")
    path = save_json("bench_span", {
        "strip": STRIP, "belt": BELT, "speed_m_s": SPEED, "n_elements_a": N_A,
        "targets": {"analyse_span_with_transport_s": TARGET_S, "eigen_agreement_rtol": AGREE_RTOL},
        "summary": summary, "a": a, "b": b, "elapsed_s": elapsed,
    })
    print(f"Saved {path}")


if __name__ == "__main__":
    main()
