"""beltjax: a JAX-differentiable simulator of belt drives.

Importing the package switches JAX to float64 (the element energies lose
meaning in float32: axial strains of 1e-3 are differences of numbers near 1).
"""

import os as _os

_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from beltjax.ancf import Section  # noqa: E402
from beltjax.span import SpanResult, analyse_span  # noqa: E402

__all__ = ["Section", "SpanResult", "analyse_span"]
__version__ = "0.1.0"
