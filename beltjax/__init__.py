"""beltjax: a JAX-differentiable simulator of belt drives.

Importing the package switches JAX to float64 (the element energies lose
meaning in float32: axial strains of 1e-3 are differences of numbers near 1)
and does nothing else to the process; a script that runs batched work on a
multi-core CPU calls :func:`beltjax.runtime.configure` first (the ``beltjax``
command, the tests and the benchmarks do).
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)
# nothing else here changes the process: thread and XLA settings are beltjax.runtime.configure(),
# which the command, the tests and the benchmarks call first (importing beltjax starts no backend)

from beltjax.ancf import Section  # noqa: E402
from beltjax.errors import BeltjaxError  # noqa: E402
from beltjax.span import SpanResult, analyse_span  # noqa: E402

#: the public API: name -> (module, attribute), imported on first use
_LAZY = {
    "load_scene": ("beltjax.scene", "load_scene"),
    "loads_scene": ("beltjax.scene", "loads_scene"),
    "parse_scene": ("beltjax.scene", "parse_scene"),
    "dumps_scene": ("beltjax.scene", "dumps_scene"),
    "write_scene": ("beltjax.scene", "write_scene"),
    "analyse_statics": ("beltjax.statics", "analyse_statics"),
    "analyse_modes": ("beltjax.drive_modal", "analyse_modes"),
    "analyse_campbell": ("beltjax.campbell", "analyse_campbell"),
    "simulate": ("beltjax.transient", "simulate"),
    "response_over_speed": ("beltjax.orders", "response_over_speed"),
    "load_sweep": ("beltjax.sweep", "load_spec"),
    "sweep_cases": ("beltjax.sweep", "cases"),
    "evaluate_cases": ("beltjax.sweep", "evaluate"),
    "load_problem": ("beltjax.optimize", "load"),
    "optimise": ("beltjax.optimize", "optimise"),
    "configure": ("beltjax.runtime", "configure"),
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'beltjax' has no attribute {name!r}")


__all__ = ["BeltjaxError", "Section", "SpanResult", "analyse_span", *_LAZY]
__version__ = "0.1.0"
