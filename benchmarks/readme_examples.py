"""Re-run every worked example of the README and save what each command prints.

Usage::

    python benchmarks/readme_examples.py            # every example
    python benchmarks/readme_examples.py sweep fit  # only those whose name contains a word

Each example is the exact command the README shows (``.venv/bin/beltjax ...`` run here as
``python -m beltjax.cli ...`` with this interpreter), run from the repository root in its own
process.  Its standard output is saved as ``benchmarks/results/readme/<name>.txt`` with the
command on the first line, and the figures the README shows are copied from the run's output
folder into ``benchmarks/figures/``.  The README quotes these files: every block that follows a
``<!-- example: NAME -->`` marker must consist of lines of ``results/readme/NAME.txt`` (in order;
a line ``...`` stands for lines left out), which ``tests/test_readme.py`` checks.  So a change
that moves a worked example shows up as a diff of the saved output when this script is re-run,
and as a failing test until the README quotes the new output.

Not a benchmark (``run_all.py`` runs only ``bench_*.py``): run it after a change to the models
or to what the commands print.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SAVED = HERE / "results" / "readme"
FIGURES = HERE / "figures"

#: name -> (command line after ``beltjax``, {figure in the output folder: name in benchmarks/figures})
EXAMPLES: dict[str, tuple[str, dict[str, str]]] = {
    "statics_T200": ("statics scenes/two_pulley_T200.toml", {"layout.png": "layout_two_pulley_T200.png"}),
    "modal_T200": ("modal scenes/two_pulley_T200.toml --modes 20", {}),
    "campbell_T200": ("campbell scenes/two_pulley_T200.toml --rpm 0:2500:25",
                      {"campbell.png": "campbell_two_pulley_T200.png"}),
    "simulate_release": ("simulate scenes/sim_two_pulley_release.toml --t-end 1",
                         {"simulation.png": "simulation_release.png"}),
    "simulate_motor_start": ("simulate scenes/sim_two_pulley_motor_start.toml --t-end 0.6",
                             {"simulation.png": "simulation_motor_start.png"}),
    "fit_tensile": ("fit identification/examples/tensile_belt_B/dataset.toml",
                    {"tensile_modulus.png": "fit_tensile_belt_B.png"}),
    "fit_bench_modal": ("fit identification/examples/bench_modal/dataset.toml", {}),
    "fit_tensioner_modal": ("fit identification/examples/tensioner_modal/dataset.toml", {}),
    "sweep_tension_EI": ("sweep scenes/two_pulley_T200.toml scenes/sweeps/two_pulley_tension_EI.toml",
                         {"sweep_frequencies.png": "sweep_two_pulley_tension_EI.png"}),
    "optimize_tensioner_pivot": ("optimize scenes/tensioner_bench_stage2.toml scenes/optimize/tensioner_pivot.toml",
                                 {"campbell_before.png": "optimize_campbell_before.png",
                                  "campbell_after.png": "optimize_campbell_after.png",
                                  "layout_before.png": "optimize_layout_before.png",
                                  "layout_after.png": "optimize_layout_after.png",
                                  "history.png": "optimize_history.png"}),
    "sweep_fead_tolerance": ("sweep scenes/fead_8pulley_friction.toml scenes/sweeps/fead_friction_tolerance.toml",
                             {"sweep_histograms.png": "sweep_fead_tolerance.png"}),
    "statics_fead": ("statics scenes/fead_8pulley.toml", {"layout.png": "layout_fead_8pulley.png"}),
    "statics_shigley": ("statics scenes/shigley_flat_belt.toml", {}),
    "campbell_fead": ("campbell scenes/fead_8pulley.toml --rpm 600:6000:100",
                      {"campbell.png": "campbell_fead_8pulley.png"}),
    "simulate_fead": ("simulate scenes/fead_8pulley.toml --t-end 1",
                      {"simulation.png": "simulation_fead_8pulley.png"}),
    "simulate_fead_decoupler": ("simulate scenes/fead_8pulley_decoupler.toml --t-end 1",
                                {"simulation.png": "simulation_fead_8pulley_decoupler.png"}),
    "simulate_fead_friction": ("simulate scenes/fead_8pulley_friction.toml --t-end 1",
                               {"simulation.png": "simulation_fead_8pulley_friction.png"}),
    "orders_fead": ("orders scenes/fead_8pulley.toml --rpm 600:6000:100",
                    {"order_maps.png": "orders_maps_fead_8pulley.png", "envelopes.png": "orders_envelopes_fead_8pulley.png",
                     "slip_margins.png": "orders_slip_margins_fead_8pulley.png",
                     "hub_loci.png": "orders_hub_loci_fead_8pulley.png"}),
    "orders_fead_hybrid": ("orders scenes/fead_8pulley_hybrid.toml --rpm 600:1600:100",
                           {"span_vibration.png": "orders_span_vibration_fead_8pulley_hybrid.png",
                            "span_vibration_maps.png": "orders_span_vibration_maps_fead_8pulley_hybrid.png",
                            "envelopes.png": "orders_envelopes_fead_8pulley_hybrid.png"}),
    "span_bench": ("span --length 0.67143 --tension 100.5 --EA 111190 --EI 0.034 --rhoA 0.12166 --elements 16",
                   {"span_modes.png": "span_modes_bench.png"}),
}


def run(name: str) -> int:
    """Run one example, save its output and figures; returns the command's exit status."""
    args, figures = EXAMPLES[name]
    SAVED.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f"beltjax-{name}-") as tmp:
        out = Path(tmp) / "out"
        cmd = [sys.executable, "-m", "beltjax.cli", *args.split(), "--out", str(out)]
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONUNBUFFERED="1")
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        text = proc.stdout.replace(str(out), "out")
        header = f"$ .venv/bin/beltjax {args} --out out\n"
        (SAVED / f"{name}.txt").write_text(header + text)
        for src, dst in figures.items():
            if (out / src).exists():
                shutil.copyfile(out / src, FIGURES / dst)
            elif proc.returncode == 0:
                print(f"{name}: figure {src} not written", file=sys.stderr)
    print(f"{name:<28} exit {proc.returncode}  {wall:7.1f} s", flush=True)
    if proc.stderr.strip() and proc.returncode != 0:
        print(proc.stderr.strip().splitlines()[-1], file=sys.stderr)
    return proc.returncode


def main(argv: list[str]) -> int:
    names = [n for n in EXAMPLES if not argv or any(w in n for w in argv)]
    if not names:
        print("no example matched", file=sys.stderr)
        return 2
    codes = [run(n) for n in names]
    return 0 if all(c == 0 for c in codes) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
