"""A sweep's chunks as tasks on a dask.distributed cluster (each worker compiles once)."""

from __future__ import annotations

import os
import threading

import jax
import jax.numpy as jnp
import numpy as np

from beltjax.scene import Scene
from beltjax.sweep.spec import SweepError
from beltjax.sweep.batch import _Options, _run_chunk


#: one JAX computation at a time per process: concurrent executions from several threads (a Dask
#: worker with threads, or several workers in one process) deadlocked XLA's CPU runtime here
_EXECUTION_LOCK = threading.Lock()

def _chunk_task(scene_np, values, rpm, opts: _Options, size: int, cache_dir: str | None, ref=None):
    """A Dask task: one chunk on a worker (the scene travels with numpy leaves)."""
    with _EXECUTION_LOCK:
        if cache_dir and not jax.config.jax_compilation_cache_dir:
            try:
                jax.config.update("jax_compilation_cache_dir", cache_dir)
                jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
            except Exception:  # pragma: no cover - a worker without a writable cache
                pass
        scene = jax.tree.map(jnp.asarray, scene_np)
        return {k: np.asarray(v) for k, v in _run_chunk(scene, values, rpm, opts, size, None, ref).items()}

def _dask_client(address):
    """(client, owned) for ``address``: a dask.distributed Client, a scheduler address, or None for a
    LocalCluster with one single-threaded worker process per core."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise SweepError("the dask backend needs dask.distributed: pip install 'beltjax[dask]'", "backend") from None
    if address is not None and not isinstance(address, str):
        return address, False
    address = address or os.environ.get("BELTJAX_DASK_SCHEDULER") or None
    if address:
        try:
            return Client(address, timeout="20s"), True
        except OSError as exc:
            raise SweepError(f"cannot reach the Dask scheduler {address!r}: {exc}", "dask_scheduler") from None
    cluster = LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    return Client(cluster), True

def _run_dask(scene: Scene, chunks: list[dict], rpm: np.ndarray, opts: _Options, size: int, dask,
              progress, post=lambda r: r, ref=None) -> list[dict]:
    """The chunks as tasks on a dask.distributed cluster (results in chunk order; ``post`` applied
    to each chunk's outputs as it arrives)."""
    from dask.distributed import as_completed

    client, owned = _dask_client(dask)
    n = sum(len(next(iter(c.values()))) for c in chunks)
    results: list = [None] * len(chunks)
    try:
        [sfut] = client.scatter([jax.tree.map(np.asarray, scene)], broadcast=True, hash=False)
        cache = jax.config.jax_compilation_cache_dir
        futs = [client.submit(_chunk_task, sfut, c, rpm, opts, size, cache, ref, pure=False) for c in chunks]
        index = {f.key: i for i, f in enumerate(futs)}
        done = 0
        for fut in as_completed(futs):
            i = index[fut.key]
            results[i] = post(fut.result())
            done += len(next(iter(chunks[i].values())))
            if progress is not None:
                progress(done, n)
    finally:
        if owned:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None:
                cluster.close()
    return results

def _dask_client_check() -> None:
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise SweepError("the dask backend needs dask.distributed: pip install 'beltjax[dask]'", "backend") from None
