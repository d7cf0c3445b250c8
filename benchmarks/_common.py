"""Shared helpers of the benchmark scripts: timing, machine info, tables, JSON.

Not a benchmark itself (``run_all.py`` runs only ``bench_*.py``).  Import it
before numpy / jax / beltjax so that ``OPENBLAS_NUM_THREADS=1`` is set before
any BLAS is loaded.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import contextlib
import datetime as _dt
import fcntl
import json
import math
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np

import beltjax  # noqa: F401  (enables float64)
from beltjax import runtime

runtime.configure()  # XLA's CPU pool and thread settings, before the first JAX computation

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"


# --------------------------------------------------------------------------- machine


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _mem_total_gib() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return round(int(line.split()[1]) / 2**20, 1)
    except OSError:
        pass
    return None


def _git_commit() -> str | None:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True, text=True, timeout=5
        )
        head = out.stdout.strip() or None
        # uncommitted changes to the code measured: the commit alone would name code that did not run
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "beltjax", "identification"], cwd=HERE.parent,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return f"{head}+uncommitted" if head and dirty else head
    except Exception:
        return None


def machine_info() -> dict:
    """CPU, cores, memory, library versions, date; stored in every result file."""
    try:
        import scipy

        scipy_version = scipy.__version__
    except ImportError:
        scipy_version = None
    import jaxlib

    return {
        "date": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "cpu_model": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "memory_gib": _mem_total_gib(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "numpy": np.__version__,
        "scipy": scipy_version,
        "beltjax": beltjax.__version__,
        "jax_backend": jax.default_backend(),
        "jax_devices": [str(d) for d in jax.devices()],
        "x64": bool(jax.config.jax_enable_x64),
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
        "git_commit": _git_commit(),
        "loadavg_1_5_15min": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }


def machine_line(info: dict) -> str:
    return (
        f"{info['cpu_model']}, {info['cpu_count']} cores, {info['memory_gib']} GiB, "
        f"jax {info['jax']} ({info['jax_backend']}, x64={info['x64']}), numpy {info['numpy']}, "
        f"scipy {info['scipy']}, OPENBLAS_NUM_THREADS={info['OPENBLAS_NUM_THREADS']}, {info['date']}, "
        f"load avg {info['loadavg_1_5_15min'][0]:.2f}"
    )


# --------------------------------------------------------------------------- timing


def block(x):
    """Wait for every jax array in x (numpy objects and others pass through)."""
    return jax.block_until_ready(x)


def time_steady(fn, *args, repeats: int = 31, min_sample_s: float = 2e-3, max_total_s: float = 2.0, **kwargs) -> dict:
    """Steady-state time of ``fn(*args)`` (s per call), median of repeated samples.

    The function is called (and blocked on) once first, so compilation is
    excluded.  Each sample runs ``number`` back-to-back calls, each one blocked
    with ``block_until_ready``, with ``number`` chosen so a sample lasts at least
    ``min_sample_s``; the per-call time of a sample is its mean.  Sampling stops
    after ``repeats`` samples or ``max_total_s`` (with at least 5 samples).
    """
    block(fn(*args, **kwargs))
    t0 = time.perf_counter()
    block(fn(*args, **kwargs))
    single = time.perf_counter() - t0
    number = max(1, int(math.ceil(min_sample_s / max(single, 1e-7))))
    samples = []
    start = time.perf_counter()
    for r in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            block(fn(*args, **kwargs))
        samples.append((time.perf_counter() - t0) / number)
        if r >= 4 and time.perf_counter() - start > max_total_s:
            break
    return {
        "median_s": statistics.median(samples),
        "min_s": min(samples),
        "max_s": max(samples),
        "samples": len(samples),
        "calls_per_sample": number,
    }


def time_interleaved(fns: dict, rounds: int = 21, min_sample_s: float = 2e-3, max_total_s: float = 4.0) -> dict:
    """Steady-state times of several zero-argument functions, sampled round-robin.

    Like ``time_steady`` but one sample of each function per round, so a
    transient load on the machine hits all of them alike (fair ratios).
    Returns {name: stats}; the stats also hold the process CPU time per call
    (``cpu_median_s``, ``cpu_min_s``: ``time.process_time``, every thread of this
    process), which other processes on a shared machine do not inflate.
    """
    numbers = {}
    for name, fn in fns.items():
        block(fn())
        t0 = time.perf_counter()
        block(fn())
        numbers[name] = max(1, int(math.ceil(min_sample_s / max(time.perf_counter() - t0, 1e-7))))
    samples = {name: [] for name in fns}
    cpu = {name: [] for name in fns}
    start = time.perf_counter()
    for r in range(rounds):
        for name, fn in fns.items():
            n = numbers[name]
            t0, c0 = time.perf_counter(), time.process_time()
            for _ in range(n):
                block(fn())
            samples[name].append((time.perf_counter() - t0) / n)
            cpu[name].append((time.process_time() - c0) / n)
        if r >= 4 and time.perf_counter() - start > max_total_s:
            break
    return {
        name: {"median_s": statistics.median(s), "min_s": min(s), "max_s": max(s), "samples": len(s),
               "calls_per_sample": numbers[name], "cpu_median_s": statistics.median(cpu[name]),
               "cpu_min_s": min(cpu[name])}
        for name, s in samples.items()
    }


def time_compile(jitted, *args, **kwargs):
    """Trace + lower and XLA-compile times of a jitted function at these arguments.

    Returns ``(compiled, {"lower_s", "compile_s", "total_s"})``; call
    ``compiled(*args)`` (dynamic arguments only) to run it.
    """
    t0 = time.perf_counter()
    lowered = jitted.lower(*args, **kwargs)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    return compiled, {"lower_s": t1 - t0, "compile_s": t2 - t1, "total_s": t2 - t0}


def time_first_call(fn, *args, **kwargs):
    """Wall time of one call, blocked (the first call of a fresh function: compile + run)."""
    t0 = time.perf_counter()
    out = block(fn(*args, **kwargs))
    return out, time.perf_counter() - t0


# --------------------------------------------------------------------------- output


def fmt_time(s: float | None) -> str:
    """Seconds as a short human string (ns / us / ms / s)."""
    if s is None or (isinstance(s, float) and math.isnan(s)):
        return "-"
    if s < 1e-6:
        return f"{s * 1e9:.0f} ns"
    if s < 1e-3:
        return f"{s * 1e6:.1f} us"
    if s < 1.0:
        return f"{s * 1e3:.2f} ms"
    return f"{s:.2f} s"


def table(headers: list[str], rows: list[list], title: str | None = None) -> str:
    """A GitHub-markdown table (aligned, so it is also readable in a terminal)."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    lines = []
    if title:
        lines += [f"### {title}", ""]
    lines.append("| " + " | ".join(c.ljust(w) for c, w in zip(cells[0], widths)) + " |")
    lines.append("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for r in cells[1:]:
        lines.append("| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |")
    return "\n".join(lines)


def dopri8_at(scene, rtol: float):
    """``scene`` with its transient on Dopri8 at ``rtol`` and atol = 1e-3 rtol (the accuracy rows)."""
    import dataclasses

    return dataclasses.replace(scene, simulation=dataclasses.replace(scene.simulation, solver="dopri8", rtol=rtol,
                                                                     atol=1e-3 * rtol))


def transient_error(res, ref, channels=("arm_angle_deg", "span_tensions_N")) -> float:
    """The worst channel's max |x - x_ref| / ptp(x_ref) over the run's second half (the start's
    transient left out: both runs start at the same state), of two ``transient.simulate`` results."""
    half = ref.t >= 0.5 * ref.t[-1]
    return max(float(np.max(np.abs(res.channels[k][half] - ref.channels[k][half]))
                     / max(float(np.ptp(ref.channels[k][half])), 1e-300)) for k in channels if k in ref.channels)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    return x


@contextlib.contextmanager
def exclusive(path: str | None):
    """Hold an exclusive lock on the file ``path`` (None: no lock) while timing, so that benchmarks
    run side by side on one machine (their compilations overlapping) time their runs one at a time."""
    if not path:
        yield
        return
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def save_json(name: str, payload: dict) -> Path:
    """Write results/<name>.json (machine info added under "machine")."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    data = {"benchmark": name, "machine": machine_info(), **payload}
    path.write_text(json.dumps(_jsonable(data), indent=2) + "\n")
    return path
