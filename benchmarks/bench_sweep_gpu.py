"""Sweep throughput on an accelerator: statics + modal of the two-pulley bench by chunk size,
the default chunk included, with each chunk's compile time (and the persistent cache's).

Run on a machine with a GPU (it runs on CPU too, slowly): ``python benchmarks/bench_sweep_gpu.py
--cases 16384 --chunks default:track,256,4096 --json benchmarks/results/sweep_gpu.json``.  Run it a
second time with the same ``--cache`` folder to time the compilation read from JAX's persistent
cache; with ``XLA_FLAGS=--xla_gpu_autotune_level=0`` to time it without XLA's autotuning.

Target (issue "Response over engine speed"): with default settings at least 15,000 cases/s of
the two-pulley bench on a GPU.  The cases are an a x b grid of installation tension (150-650 N)
and belt EI (0.02-0.05 N m^2); each is the statics (Newton from the installed state) and the
modal analysis (20 lowest frequencies), as ``bench_sweep.py`` on CPU.  A few cases are checked
against the same function compiled for the CPU (the largest relative difference of the
frequencies is reported).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import functools
import json
import os
import time
from pathlib import Path

import jax
import numpy as np

from beltjax import drive, runtime, sweep
from beltjax.sweep import batch as sweep_batch
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = ("statics", "modal")
MODES = 20
TARGET_CASES_PER_S = 15000.0


def _grid(n: int) -> dict[str, np.ndarray]:
    a = int(np.sqrt(n))
    b = -(-n // a)
    T, EI = np.meshgrid(np.linspace(150.0, 650.0, a), np.linspace(0.02, 0.05, b), indexing="ij")
    return {"belt.static_tension": T.reshape(-1)[:n], "belt.EI": EI.reshape(-1)[:n]}


def _cpu_reference(scene, values, idx) -> np.ndarray:
    """Frequencies of cases ``idx`` from the single-case function compiled for the CPU (Hz)."""
    cpu = jax.devices("cpu")[0]
    single = jax.jit(functools.partial(sweep.case_outputs, outputs=OUTPUTS, modes=MODES))
    full = sweep.full_values(scene, {k: v[:1] for k, v in values.items()})
    out = []
    with jax.default_device(cpu):
        for i in idx:
            case = {k: np.float64(np.asarray(v).reshape(-1)[0]) for k, v in full.items()}
            case.update({k: np.float64(v[i]) for k, v in values.items()})
            out.append(np.asarray(single(scene, case)["frequencies_hz"]))
    return np.stack(out)


def one_chunk_size(scene, values, chunk: int | None, track: bool) -> dict:
    """Compile time (first call of one chunk less a second call) and the whole sweep's rate;
    ``track``: with the mode tracking of the default settings (``reference="auto"``)."""
    ref = "auto" if track else None
    n = len(next(iter(values.values())))
    n_ind = drive.n_independent(scene)
    size = sweep._chunk_size(n, chunk, 0, sweep._devices(), n_ind)
    first = {k: v[:size] for k, v in values.items()}
    t0 = time.perf_counter()
    sweep.evaluate(scene, first, OUTPUTS, MODES, chunk=chunk, reference=ref)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    sweep.evaluate(scene, first, OUTPUTS, MODES, chunk=chunk, reference=ref)
    t_again = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = sweep.evaluate(scene, values, OUTPUTS, MODES, chunk=chunk, reference=ref)
    wall = time.perf_counter() - t0
    ok = float(np.mean(res["status"] == "ok"))
    return dict(chunk=size, requested="default" if chunk is None else chunk, tracked=track, first_chunk_s=t_first,
                compile_s=t_first - t_again, chunk_s=t_again, device_s=_device_time(scene, first, chunk, ref), cases=n,
                wall_s=wall, cases_per_s=n / wall, share_ok=ok, frequencies_hz=res["frequencies_hz"])


def _device_time(scene, first, chunk, ref) -> float:
    """One chunk's compiled batch alone (s): from its launch until its outputs are ready on the
    device, without the host's work (transfers, tracking) that the chunk time includes."""
    times, launch = [], sweep_batch._launch_chunk

    def timed(*a, **k):
        t0 = time.perf_counter()
        r = launch(*a, **k)
        jax.block_until_ready(r[-1])
        times.append(time.perf_counter() - t0)
        return r

    sweep_batch._launch_chunk = timed
    try:
        sweep.evaluate(scene, first, OUTPUTS, MODES, chunk=chunk, reference=ref)
    finally:
        sweep_batch._launch_chunk = launch
    return times[0]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=16384)
    ap.add_argument("--chunks", default="default:track,256,4096",
                    help="comma-separated chunk sizes ('default'; ':track' adds the default mode tracking)")
    ap.add_argument("--cache", default=None, help="JAX persistent compilation cache folder (off if not given)")
    ap.add_argument("--json", default=None, help="write the results here")
    ap.add_argument("--label", default="", help="a note saved with the results (e.g. the XLA flags)")
    ap.add_argument("--cpu", action="store_true", help="run on a CPU too (else a CPU-only machine skips)")
    args = ap.parse_args()
    if jax.devices()[0].platform == "cpu" and not args.cpu:
        print("bench_sweep_gpu: no accelerator here; skipped (--cpu runs it on the CPU)")
        return
    if args.cache:
        os.environ["BELTJAX_CACHE"] = args.cache
        runtime.enable_compile_cache()
    info = _common.machine_info()
    dev = jax.devices()[0]
    try:
        mem = (dev.memory_stats() or {}).get("bytes_limit")
    except Exception:
        mem = None
    info.update(device=str(dev), device_kind=getattr(dev, "device_kind", dev.platform), device_bytes_limit=mem,
                jax=jax.__version__, xla_flags=os.environ.get("XLA_FLAGS", ""), label=args.label,
                cache=args.cache)
    print(_common.machine_line(info), "|", info["device_kind"], "|", jax.__version__, "|",
          info["xla_flags"] or "default XLA flags", "| cache:", args.cache or "off", flush=True)
    scene = drive.canonical(load_scene(ROOT / "scenes" / "two_pulley_T200.toml"))
    n_ind = drive.n_independent(scene)
    values = _grid(args.cases)
    print(f"two-pulley bench, {n_ind} independent coordinates; {args.cases} cases (statics + {MODES} modes); "
          f"default chunk here {sweep.default_chunk(sweep._devices(), n_ind)}", flush=True)
    rows = []
    for c in args.chunks.split(","):
        c, _, track = c.strip().partition(":")
        r = one_chunk_size(scene, values, None if c == "default" else int(c), track == "track")
        rows.append(r)
        print(f"chunk {r['chunk']:>5} ({r['requested']}{', tracked' if r['tracked'] else ''}): compile {r['compile_s']:6.1f} s, one chunk "
              f"{r['chunk_s'] * 1e3:8.1f} ms (on the device {r['device_s'] * 1e3:6.1f} ms), {r['cases']} cases in {r['wall_s']:6.2f} s = "
              f"{r['cases_per_s']:9.0f} cases/s, ok {r['share_ok']:.3f}", flush=True)
    idx = np.linspace(0, args.cases - 1, 8).astype(int)
    ref = _cpu_reference(scene, values, idx)
    for r in rows:
        # sorted: tracked columns follow the nominal's modes, the reference's are sorted
        F = np.sort(np.asarray(r.pop("frequencies_hz"))[idx], axis=1)
        r["max_rel_diff_vs_cpu"] = float(np.nanmax(np.abs(F[:, 1:] / np.sort(ref, axis=1)[:, 1:] - 1)))
    print("largest relative difference of the frequencies against the CPU (8 cases): "
          + ", ".join(f"chunk {r['chunk']}: {r['max_rel_diff_vs_cpu']:.1e}" for r in rows), flush=True)
    default = next((r for r in rows if r["requested"] == "default" and r["tracked"]), None)
    if default is not None:
        print(f"default settings: {default['cases_per_s']:.0f} cases/s against the target "
              f"{TARGET_CASES_PER_S:.0f} ({'met' if default['cases_per_s'] >= TARGET_CASES_PER_S else 'NOT met'})")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(dict(machine=info, n_independent=n_ind, modes=MODES, rows=rows,
                                                   target_cases_per_s=TARGET_CASES_PER_S), indent=1, default=str))


if __name__ == "__main__":
    main()
