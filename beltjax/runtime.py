"""Process set-up for beltjax's batched work on CPU: done by the ``beltjax`` command, the tests and
the benchmarks, or by a script as its first call, never by ``import beltjax`` (which only
switches JAX to float64, the physics' requirement, and starts no JAX backend).

:func:`configure` must run before the process's first JAX computation:

- ``XLA_FLAGS``: XLA's Eigen kernels single-threaded (vmapped eigen-solves hung intermittently
  in XLA's multi-threaded Eigen pool on CPU, a known JAX CPU deadlock; single-threaded Eigen
  costs nothing measurable at these sizes); ``OPENBLAS_NUM_THREADS=1`` as a default for a BLAS
  not loaded yet;
- XLA's CPU client created with an intra-op pool of one thread.  XLA runs batched LAPACK calls
  (vmapped Cholesky, triangular solves, eigh) through jax::ParallelBatchMap on that pool; when
  such a call itself runs on a pool worker (as the continuation of a dot), it waits for tasks
  queued behind it and the process deadlocks with every thread asleep (seen with jax 0.10 on 2
  cores: a vmapped jacfwd through statics + eigenvalues, and optax L-BFGS steps, hung after
  minutes).  A pool of one thread cannot wait on itself: the client is created while this
  thread is pinned to one core (pool sizes follow the affinity mask), then every thread gets
  the whole machine back.  XLA's CPU kernels at these sizes are single-threaded anyway.
  ``BELTJAX_CPU_POOL=default`` keeps XLA's pool.

:func:`enable_compile_cache` switches on JAX's persistent compilation cache (the command does,
so that a second run of like scenes skips most of the compilation).
"""

from __future__ import annotations

import contextlib
import os
import pathlib

_DONE = False


def _single_thread_cpu_pool():
    import jax

    if os.environ.get("BELTJAX_CPU_POOL") == "default" or not hasattr(os, "sched_getaffinity"):
        jax.devices("cpu")
        return
    cpus = os.sched_getaffinity(0)
    if len(cpus) < 2:
        jax.devices("cpu")
        return
    os.sched_setaffinity(0, {min(cpus)})
    try:
        jax.devices("cpu")
    finally:
        # every thread started meanwhile (XLA's workers) inherited the one-core mask: give all
        # of them, not only this one, the whole machine back (the pool keeps its one thread)
        try:
            tids = [int(t) for t in os.listdir("/proc/self/task")]
        except OSError:
            tids = [0]
        for tid in tids:
            try:
                os.sched_setaffinity(tid, cpus)
            except OSError:
                pass


def configure() -> bool:
    """Set this process up for beltjax (see the module docstring).  Idempotent; returns False,
    changing nothing, when a JAX backend was started before (too late to set it up)."""
    global _DONE
    if _DONE:
        return True
    from jax._src import xla_bridge

    if xla_bridge.backends_are_initialized():
        return False
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()
    _single_thread_cpu_pool()
    _DONE = True
    return True


def enable_compile_cache():
    """JAX's persistent compilation cache in ``$BELTJAX_CACHE`` (default ~/.cache/beltjax/jax);
    a read-only home runs without it."""
    import jax

    cache = pathlib.Path(os.environ.get("BELTJAX_CACHE", pathlib.Path.home() / ".cache" / "beltjax" / "jax"))
    try:
        cache.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(cache))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # a read-only home: run without the cache
        pass


@contextlib.contextmanager
def cacheable():
    """Trace within this context for a program JAX's persistent compilation cache can keep.

    diffrax checks its inputs (dt0's sign, SaveAt.ts ordered and within [t0, t1]) with
    equinox's ``error_if``, which compiles to host callbacks, and JAX never writes a program with
    host callbacks to its persistent cache: every run of a transient recompiled its integrator
    (28-78 s for the eight-pulley hybrid drive).  Inside this context those checks give NaN
    instead (equinox's ``on_error="nan"``), which the callers' finiteness checks report; their
    inputs satisfy the checks by construction.  Without equinox's private switch (another
    equinox version) it does nothing: the program still runs, only uncached.
    """
    try:
        from equinox import _errors
    except ImportError:  # pragma: no cover
        yield
        return
    old = getattr(_errors, "EQX_ON_ERROR", None)
    if old is None:  # pragma: no cover
        yield
        return
    _errors.EQX_ON_ERROR = "nan"
    try:
        yield
    finally:
        _errors.EQX_ON_ERROR = old


@contextlib.contextmanager
def sigterm_as_exit():
    """Within this block SIGTERM ends the process as SystemExit(143) after one line on stderr,
    so that every ``finally`` runs: a command's staged outputs (:mod:`beltjax.outputs`) are
    thrown away rather than left beside ``--out``.  The previous handler comes back after the
    block; off the main thread (where no handler can be set) the block changes nothing."""
    import signal
    import sys
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(signum, frame):
        sys.stderr.write("\nbeltjax: terminated\n")
        raise SystemExit(128 + signum)

    old = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)
