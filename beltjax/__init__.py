"""beltjax: a JAX-differentiable simulator of belt drives.

Importing the package switches JAX to float64 (the element energies lose
meaning in float32: axial strains of 1e-3 are differences of numbers near 1).
"""

import os as _os

_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# vmapped eigen-solves hung intermittently in XLA's multi-threaded Eigen pool on CPU (a known
# JAX CPU deadlock); single-threaded Eigen costs nothing measurable at these sizes.
if "xla_cpu_multi_thread_eigen" not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

import jax as _jax

_jax.config.update("jax_enable_x64", True)
# XLA's CPU client runs batched LAPACK calls (vmapped Cholesky, triangular solves, eigh)
# through jax::ParallelBatchMap on its intra-op thread pool; when such a call itself runs on a
# pool worker (as the continuation of a dot), it waits for tasks queued behind it and the
# process deadlocks with every thread asleep (seen with jax 0.10 on 2 cores: a vmapped
# jacfwd through statics + eigenvalues, and optax L-BFGS steps, hung after minutes).  A pool
# of one thread cannot wait on itself: the CPU client is created while this thread is pinned
# to one core (pool sizes follow the affinity mask), then the mask is restored.  XLA's CPU
# kernels at these sizes are single-threaded anyway.  BELTJAX_CPU_POOL=default keeps XLA's.
def _single_thread_cpu_pool():
    if _os.environ.get("BELTJAX_CPU_POOL") == "default" or not hasattr(_os, "sched_getaffinity"):
        return
    cpus = _os.sched_getaffinity(0)
    if len(cpus) < 2:
        return
    _os.sched_setaffinity(0, {min(cpus)})
    try:
        _jax.devices("cpu")
    finally:
        # every thread started meanwhile (XLA's workers) inherited the one-core mask: give all
        # of them, not only this one, the whole machine back (the pool keeps its one thread)
        try:
            tids = [int(t) for t in _os.listdir("/proc/self/task")]
        except OSError:
            tids = [0]
        for tid in tids:
            try:
                _os.sched_setaffinity(tid, cpus)
            except OSError:
                pass


_single_thread_cpu_pool()

from beltjax.ancf import Section  # noqa: E402
from beltjax.errors import BeltjaxError  # noqa: E402
from beltjax.span import SpanResult, analyse_span  # noqa: E402

#: the public API beyond the span: name -> module that holds it (imported on first use)
_LAZY = {
    "load_scene": "beltjax.scene",
    "loads_scene": "beltjax.scene",
    "parse_scene": "beltjax.scene",
    "analyse_statics": "beltjax.statics",
    "analyse_modes": "beltjax.drive_modal",
    "analyse_campbell": "beltjax.campbell",
    "simulate": "beltjax.transient",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'beltjax' has no attribute {name!r}")


__all__ = ["BeltjaxError", "Section", "SpanResult", "analyse_span", *_LAZY]
__version__ = "0.1.0"
