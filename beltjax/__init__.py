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

from beltjax.ancf import Section  # noqa: E402
from beltjax.span import SpanResult, analyse_span  # noqa: E402

__all__ = ["Section", "SpanResult", "analyse_span"]
__version__ = "0.1.0"
