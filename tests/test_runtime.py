"""Importing beltjax changes nothing in the process but float64 (issue 21): no JAX backend is
started, no environment variable and no thread affinity is touched; beltjax.runtime.configure()
does the set-up, once, and refuses (returns False) once a backend runs."""

from __future__ import annotations

import subprocess
import sys

CHECK = r"""
import os
env0, aff0 = dict(os.environ), (os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None)
import beltjax, beltjax.cli, beltjax.statics, beltjax.drive_modal, beltjax.campbell, beltjax.transient
import beltjax.sweep, beltjax.optimize, beltjax.plot_drive, identification.fit
from jax._src import xla_bridge
import jax
assert jax.config.jax_enable_x64
assert not xla_bridge.backends_are_initialized(), "importing beltjax started a JAX backend"
assert dict(os.environ) == env0, "importing beltjax changed the environment"
assert aff0 is None or os.sched_getaffinity(0) == aff0
from beltjax import runtime
assert runtime.configure() and runtime.configure()
assert "--xla_cpu_multi_thread_eigen=false" in os.environ["XLA_FLAGS"]
assert xla_bridge.backends_are_initialized()
assert aff0 is None or os.sched_getaffinity(0) == aff0, "configure left the thread pinned"
print("ok")
"""

LATE = r"""
import jax.numpy as jnp
import beltjax
jnp.ones(2).block_until_ready()
from beltjax import runtime
assert runtime.configure() is False
print("ok")
"""


def _run(code):
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("XLA_FLAGS", "OPENBLAS_NUM_THREADS")}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)


def test_import_sets_nothing_up_and_configure_does():
    r = _run(CHECK)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]


def test_configure_after_a_backend_started_is_refused():
    r = _run(LATE)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]


def test_sigterm_discards_a_command_s_staged_outputs(tmp_path):
    """SIGTERM (what timeout(1), schedulers and `docker stop` send) ends a command as
    SystemExit(143) with every ``finally`` run: its staged outputs are thrown away, nothing is left
    beside --out, and the previous handler comes back."""
    import os
    import signal

    from beltjax import outputs, runtime

    before = signal.getsignal(signal.SIGTERM)
    target = tmp_path / "out"
    try:
        with runtime.sigterm_as_exit(), outputs.staged(target) as stage:
            (stage.folder() / "partial.json").write_text("{}")
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs between bytecodes
                pass
        raise AssertionError("SIGTERM did not end the block")
    except SystemExit as exc:
        assert exc.code == 143
    assert list(tmp_path.iterdir()) == [] and signal.getsignal(signal.SIGTERM) is before
