"""Run every benchmark script ``benchmarks/bench_*.py``, one after the other.

Usage::

    python benchmarks/run_all.py              # all bench_*.py (picks up new ones automatically)
    python benchmarks/run_all.py span element # only those whose name contains one of the words

Each script runs in its own Python process (fresh JAX caches, so compile times
are cold) with ``OPENBLAS_NUM_THREADS=1``; its output is streamed and it saves
``benchmarks/results/<name>.json`` itself.  A summary (script, exit code,
wall time) is printed at the end and written to ``results/run_all.json``; the
exit code is non-zero when any script failed.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    scripts = sorted(HERE.glob("bench_*.py"))
    if argv:
        scripts = [s for s in scripts if any(word in s.stem for word in argv)]
    if not scripts:
        print("no benchmark scripts matched", file=sys.stderr)
        return 2
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    summary = []
    for script in scripts:
        print(f"\n{'=' * 100}\n== {script.name}\n{'=' * 100}", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.run([sys.executable, str(script)], cwd=HERE.parent, env=env).returncode
        wall = time.perf_counter() - t0
        summary.append({"script": script.name, "returncode": rc, "wall_s": round(wall, 2)})

    print(f"\n{'=' * 100}\n== summary\n{'=' * 100}")
    width = max(len(s["script"]) for s in summary)
    for s in summary:
        status = "ok" if s["returncode"] == 0 else f"FAILED (exit {s['returncode']})"
        print(f"{s['script']:<{width}}  {s['wall_s']:8.1f} s  {status}")
    results = HERE / "results"
    results.mkdir(exist_ok=True)
    (results / "run_all.json").write_text(json.dumps(
        {"date": dt.datetime.now().astimezone().isoformat(timespec="seconds"), "python": sys.executable,
         "scripts": summary}, indent=2) + "\n")
    write_summary(results)
    return 0 if all(s["returncode"] == 0 for s in summary) else 1


def write_summary(results: Path) -> None:
    """Collect the headline figures of every results/bench_*.json (and results/transient.json) into
    benchmarks/summary.json."""
    headline = {}
    files = sorted(results.glob("bench_*.json"))
    files += [f for f in (results / "transient.json",) if f.exists()]  # written by bench_transient.py
    for f in files:
        data = json.loads(f.read_text())
        headline[f.stem] = {"machine": data.get("machine"), "summary": data.get("summary")}
    (HERE / "summary.json").write_text(json.dumps(headline, indent=2) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] == ["--summary-only"]:  # rebuild summary.json from the saved results
        write_summary(HERE / "results")
        sys.exit(0)
    sys.exit(main(sys.argv[1:]))
