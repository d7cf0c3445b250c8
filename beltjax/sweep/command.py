"""``beltjax sweep``: load, evaluate, write the outputs, print the summary."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from beltjax import drive, mode_tracking, sweep_modes
from beltjax.scene import Scene
from beltjax.sweep.spec import cases, load_spec
from beltjax.sweep.batch import _chunk_size, _devices, evaluate
from beltjax.sweep.dask_backend import _dask_client_check
from beltjax.sweep.tables import columns, report, summary_table, write_campbell_csv, write_csv
from beltjax.sweep.figures import plots
from beltjax import outputs


def progress_bar(label: str = "sweep") -> Callable[[int, int], None]:
    """A progress callback drawing ``label [#####     ] done/total cases (elapsed)`` on stderr
    (:func:`beltjax.progress.counter`: redrawn in place on a terminal, whole lines elsewhere)."""
    from beltjax.progress import counter

    return counter(f"  {label}", "cases")

def run(scene: Scene, spec_path: str | os.PathLike, out: str | os.PathLike, backend: str = "local") -> int:
    """``beltjax sweep``: read the sweep file, evaluate every case, write sweep.csv, sweep.json and
    plots to ``out``, print a summary; returns the exit status (1 when every case failed).

    Raises :class:`SweepError` (one line naming the key) for a bad sweep file.
    """
    spec = load_spec(spec_path)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    values = cases(scene, spec)
    n = spec.n_cases
    print(f"sweep of {scene.source} by {spec.source}: {n} cases"
          + (f" (grid {' x '.join(str(s) for s in spec.grid_shape)})" if spec.grid else "")
          + (f" ({spec.samples} random samples{' per grid point' if spec.grid else ''})" if spec.random else "")
          + f"; outputs {', '.join(spec.outputs)}; backend {backend}")
    if backend == "dask":
        _dask_client_check()
    refs = (sweep_modes.references(scene, spec.outputs, spec.modes, spec.rpm)
            if "modal" in spec.outputs or "campbell" in spec.outputs else {})
    ref = refs.get("modal") if "modal" in spec.outputs else refs.get("campbell")
    nominal = (list(ref[1]), [float(x) for x in ref[0].freqs]) if ref else None
    labels = nominal[0] if nominal else None
    t0 = time.perf_counter()
    first: list[float] = []
    bar = progress_bar()

    def progress(done, total):
        if not first:
            first.append(time.perf_counter() - t0)
        bar(done, total)

    result = evaluate(scene, values, spec.outputs, spec.modes, spec.rpm, chunk=spec.chunk, progress=progress,
                      backend=backend, dask=spec.dask_scheduler, reference=refs or None,
                      settle_s=spec.settle_s)
    wall = time.perf_counter() - t0
    devices = _devices() if backend == "local" else None
    size = _chunk_size(n, spec.chunk, 0 if spec.rpm is None else len(spec.rpm), devices,
                      drive.n_independent(scene))
    steady = (n - size) / (wall - first[0]) if first and n > size and wall > first[0] else None
    timing = {"backend": backend, "devices": [str(d) for d in (devices or jax.local_devices()[:1])]
              if backend == "local" else None, "chunk": size, "wall_s": wall,
              "first_chunk_s": first[0] if first else None, "cases_per_s": n / wall if wall > 0 else None,
              "cases_per_s_after_first_chunk": steady}
    data = report(scene, spec, values, result, nominal, timing)
    cols = columns(scene, result)
    write_csv(out / "sweep.csv", values, cols, result["status"])
    outputs.write_json(out / "sweep.json", data)
    files = [out / "sweep.csv", out / "sweep.json"]
    if "campbell_hz" in result:
        write_campbell_csv(out / "sweep_campbell.csv", result)
        files.append(out / "sweep_campbell.csv")
    files += plots(scene, spec, result, out, labels)
    print(f"{n} cases in {wall:.1f} s ({n / wall:.3g} cases/s"
          + (f"; {steady:.3g} cases/s after the first chunk, which compiles in {first[0]:.1f} s" if steady else "")
          + ")")
    print(f"{data['ok']} ok, {data['failed']} failed, {data['unstable']} unstable"
          + (f", {data['flagged']} flagged (numbers kept in sweep.csv beside the status, left out of the "
             "statistics)" if data["flagged"] else ""))
    for s, v in data["failures"].items():
        print(f"  {s}: {v['count']} cases ({v['reason']}); first: {', '.join(str(i) for i in v['cases'][:8])}")
    print(summary_table(cols, data["summary"], labels))
    for c, v in data["slipping"].items():
        if v["count"]:
            print(f"WARNING: in {v['count']} of {n} cases the belt would slip {v['where']} ({c} <= 0); "
                  f"first: {', '.join(str(i) for i in v['cases'][:8])}")
    if labels:
        print("(f<k>: the nominal scene's k-th mode, followed into every case by its shape; mode_match: a case's "
              "lowest MAC with the nominal's modes)")
        low = np.asarray(cols.get("mode_match", []), float)
        n_low = int(np.sum(low < mode_tracking.UNCERTAIN_MAC))
        if n_low:
            print(f"note: in {n_low} cases a mode's shape differs from the nominal's (mode_match < "
                  f"{mode_tracking.UNCERTAIN_MAC:g}; NaN: not found): its column holds the closest mode")
    from beltjax.outputs import wrote

    wrote(files)  # printed here, or by the command line once the files are moved into --out
    if data["ok"] + data["unstable"] + data["flagged"] == 0:
        print("beltjax: every case failed (see the status column of sweep.csv)", file=sys.stderr)
        return 1
    return 0
