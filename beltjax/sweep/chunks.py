"""How a sweep's cases are cut into compiled batches: the devices a batch is sharded over and the
chunk size, from the device kind, its memory and the problem's size (few shapes: on a GPU every
shape is a compilation of 40-50 s)."""

from __future__ import annotations

import math

import jax

from beltjax.sweep.spec import CAMPBELL_CHUNK_POINTS, SweepError


def _devices(devices="auto") -> tuple | None:
    """Devices to shard a batch over (None: no sharding).  "auto": every local device when there
    are several accelerators (GPU/TPU).  Several CPU "devices" (``--xla_force_host_platform_device_count``)
    share the same cores, and XLA's CPU runtime wedged here (all threads idle) running the batched
    eigen-solves on two of them, so CPU devices are used only when passed explicitly."""
    if devices is None:
        return None
    if isinstance(devices, str):
        if devices != "auto":
            raise SweepError(f"\"auto\", None or a sequence of JAX devices, got {devices!r}", "devices")
        devs = jax.local_devices()
        return tuple(devs) if len(devs) > 1 and devs[0].platform != "cpu" else None
    devs = tuple(devices)
    return devs if len(devs) > 1 else None


# Accelerator chunks: the case's working set is taken as ACCEL_WORDS_PER_CASE n^2 float64 words
# (n independent coordinates: the Newton Jacobian, the stiffness and mass matrices, the eigen
# solver's workspace and the forward-mode tangents), and a chunk may fill ACCEL_MEMORY_FRACTION
# of the device's memory; chunks are powers of two between ACCEL_MIN_CHUNK and ACCEL_MAX_CHUNK
# (few shapes: every shape is a compilation of 40-50 s on a GPU).  Measured on one H100 (issue
# 24): the two-pulley bench ran 4,400 cases/s in chunks of 64 and 19,300 in chunks of 1024.
ACCEL_WORDS_PER_CASE = 64
ACCEL_MEMORY_FRACTION = 0.25
ACCEL_MIN_CHUNK, ACCEL_MAX_CHUNK = 64, 4096
ACCEL_FALLBACK_BYTES = 16 * 2**30  # a device that does not report its memory


def _pow2_floor(x: float) -> int:
    return 1 << max(0, int(math.floor(math.log2(max(1.0, x)))))


def _pow2_ceil(x: float) -> int:
    return 1 << max(0, int(math.ceil(math.log2(max(1.0, x)))))


def _device_bytes(device) -> int:
    """The device's memory in bytes (its allocator's limit), or ACCEL_FALLBACK_BYTES."""
    try:
        stats = device.memory_stats() or {}
    except Exception:  # a backend without memory statistics
        stats = {}
    return int(stats.get("bytes_limit") or ACCEL_FALLBACK_BYTES)


def default_chunk(devices: tuple | None = None, n_coordinates: int | None = None) -> int:
    """Default cases per compiled batch: 1 per CPU device; on accelerators, from the device's
    memory and the problem's size (``n_coordinates``: independent coordinates of a case).

    On CPU a batch is slower per case than one case at a time: the batched arrays leave the
    cache (each fused operation streams over the whole batch) and batched LAPACK calls are
    loops; a vmapped Newton also iterates until its slowest case converges.  Two-pulley bench
    (130 coordinates), statics + modes, interleaved on the shared 2-core machine: 4.2-5.1 ms
    per case in batches of 1, 3.9-8.9 ms of 2, 6-11 ms of 4, 13-19 ms of 8 and 13-20 ms of 32,
    against 5.0-5.5 ms for the jitted single case (benchmarks/bench_sweep.py).  On a GPU a
    batch pays until the device is full: the largest power of two whose working set
    (ACCEL_WORDS_PER_CASE n^2 words per case) fits ACCEL_MEMORY_FRACTION of the memory, between
    ACCEL_MIN_CHUNK and ACCEL_MAX_CHUNK per device (benchmarks/bench_sweep_gpu.py).
    """
    devs = devices or tuple(jax.local_devices()[:1])
    if devs[0].platform == "cpu":
        return len(devs)
    n = max(1, int(n_coordinates or 256))
    fit = ACCEL_MEMORY_FRACTION * _device_bytes(devs[0]) / (8.0 * ACCEL_WORDS_PER_CASE * n * n)
    return len(devs) * min(ACCEL_MAX_CHUNK, max(ACCEL_MIN_CHUNK, _pow2_floor(fit)))


def _chunk_size(n: int, chunk: int | None, n_rpm: int, devices: tuple | None,
                n_coordinates: int | None = None) -> int:
    """Cases per compiled batch: ``chunk`` (default :func:`default_chunk`; fewer for campbell, to
    bound memory), at most the cases rounded up (to 8 on CPU, to a power of two on accelerators,
    whose compilations cost more: fewer shapes), a multiple of the device count."""
    devs = devices or tuple(jax.local_devices()[:1])
    n_dev = len(devices) if devices else 1
    chunk = default_chunk(devices, n_coordinates) if chunk is None else chunk
    cpu = devs[0].platform == "cpu"
    # campbell: every case is n_rpm modal problems (CAMPBELL_CHUNK_POINTS of them per chunk on
    # CPU, as many as the memory rule allows on accelerators)
    points = CAMPBELL_CHUNK_POINTS if cpu else default_chunk(devices, n_coordinates)
    size = chunk if n_rpm == 0 else max(1, min(chunk, points // n_rpm))
    cap = 8 * math.ceil(n / 8) if cpu else _pow2_ceil(n)
    size = min(size, cap)
    return n_dev * math.ceil(size / n_dev)
