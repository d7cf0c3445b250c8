"""Shared fixtures: the thesis' printed numbers (read, never copied)."""

import json
import pathlib

import pytest

import beltjax  # noqa: F401  (enables float64 before any array is made)
from beltjax import runtime

runtime.configure()  # XLA's CPU pool and thread settings, before the first JAX computation

REPO = pathlib.Path(__file__).resolve().parents[1]
REFERENCE = REPO.parent / "shared" / "reference" / "thesis_reference.json"


#: memory one test worker process can reach (measured: 3.8 GiB resident late in a run)
WORKER_GIB = 4.5


def pytest_xdist_auto_num_workers(config):
    """Worker processes for ``-n auto`` (pyproject's addopts): one per core, as many as the
    memory holds (WORKER_GIB each), at least one.  Two workers halve the suite's time on CI's two
    cores; a machine too small for two runs one."""
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:
        with open("/proc/meminfo") as f:
            total = next(int(line.split()[1]) for line in f if line.startswith("MemTotal:")) / 2**20
    except (OSError, StopIteration, ValueError):
        total = WORKER_GIB
    return max(1, min(cores, int(total // WORKER_GIB)))


@pytest.fixture(scope="session")
def ref():
    """The thesis reference numbers (../shared/reference/thesis_reference.json)."""
    with open(REFERENCE) as f:
        return json.load(f)


@pytest.fixture(scope="session")
def strip(ref):
    """The thesis' steel strip (Table 3.1) as (L, EA, EI, rhoA)."""
    p = ref["cantilever_strip"]["properties"]
    return p["L"], p["E"] * p["A"], p["E"] * p["I"], p["rho"] * p["A"]


@pytest.fixture(autouse=True)
def _persistent_compile_cache_off_after_each_test():
    """The in-process command-line tests switch JAX's persistent compilation cache on for the
    whole process (beltjax.runtime.enable_compile_cache, every compilation written to disk);
    switch it off again after each test, so that the rest of the suite compiles in memory only.
    Left on, a full run wrote every later compilation to disk, and twice in a row aborted
    inside JAX's cache write (put_executable_and_time) in test_sweep, 85 % into the run."""
    yield
    import jax
    from jax._src import compilation_cache

    if jax.config.jax_compilation_cache_dir is not None:
        jax.config.update("jax_compilation_cache_dir", None)
        compilation_cache.reset_cache()


@pytest.fixture(autouse=True, scope="module")
def _compiled_functions_freed_after_each_module():
    """Free every compiled function when a test module ends (the modules share compiled
    functions within themselves, through module fixtures).  Kept for the whole run, the
    executables of some 500 tests accumulated until XLA crashed while compiling in
    test_sweep, 85 % into the run (a segmentation fault in backend_compile_and_load, and
    before it an abort inside the cache write), twice on this 2-core machine."""
    yield
    import ctypes
    import gc

    import jax

    jax.clear_caches()
    gc.collect()
    try:  # hand the freed heap back to the system (glibc keeps it otherwise): two workers share the memory
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
