"""What each FEAD component costs a transient: the eight-pulley drive at idle, rotational model,
with one component changed at a time.

Run: ``python benchmarks/bench_components.py`` (about 3 min); writes
``benchmarks/results/components.json``.  ``--accuracy`` (about 8 min) adds each component's row
of the accuracy-time atlas: the same runs at rtol 1e-3, 1e-4, 1e-6 and 1e-8 (atol 1e-3 rtol),
each timed after its compilation (the least of three calls), with the error of the arm angle and the span tensions against
rtol 1e-10 (max |x - x_ref| / peak-to-peak of x_ref over the second half of the run, the worst
channel); ``results/components_accuracy.json``.

Each variant runs 1 s of idle (Dopri8, rtol 1e-6, the default) twice: the first call compiles,
the second is timed.  Variants: the scene as shipped (2nd and 4th crank orders, viscous
tensioner), one crank harmonic instead of the orders, the dry-friction tensioner with stops
(scenes/fead_8pulley_friction.toml), the alternator decoupler (scenes/fead_8pulley_decoupler.toml)
and a crank isolator (400 N m/rad, 0.3 N m s/rad).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import json
import re
import time
from pathlib import Path


from beltjax import drive, transient
from beltjax.scene import loads_scene

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
T_END = 1.0


def variants() -> dict[str, str]:
    base = (SCENES / "fead_8pulley.toml").read_text()
    one = re.sub(r"\[\[fluctuation\]\].*(?:\n(?!\[).*)*\n?", "", base).replace(
        'speed_rpm = 800.0            # idle',
        'speed_rpm = 800.0            # idle\nfluctuation_amplitude_deg = 0.5\nfluctuation_frequency_hz = 26.6667', 1)
    return {
        "as shipped: 2nd + 4th orders, viscous tensioner": base,
        "one crank harmonic (2nd order only)": one,
        "dry-friction tensioner with stops": (SCENES / "fead_8pulley_friction.toml").read_text(),
        "alternator decoupler": (SCENES / "fead_8pulley_decoupler.toml").read_text(),
        "crank isolator (400 N m/rad)": base + '\n[isolator]\npulley = "crank"\nstiffness = 400.0\ndamping = 0.3\n',
    }


#: the accuracy part's tolerances and its reference
RTOLS, RTOL_REF = (1e-3, 1e-4, 1e-6, 1e-8), 1e-10
#: timed calls per row after the compiling one (the least is kept: this machine's runs scatter 10-20 %)
REPEATS = 3
#: the channels whose error is taken
ERROR_CHANNELS = ("arm_angle_deg", "span_tensions_N")


def accuracy(info) -> None:
    """Each variant at RTOLS against RTOL_REF: steps, wall per simulated s after compilation, error."""
    rows = []
    print(f"{'variant':<50} {'rtol':>7} {'steps':>7} {'wall / sim. s':>14} {'vs real time':>13} {'error':>9}")
    for name, text in variants().items():
        sc = loads_scene(text)
        ref = transient.simulate(_common.dopri8_at(sc, RTOL_REF), T_END)
        for rtol in RTOLS:
            case = _common.dopri8_at(sc, rtol)
            transient.simulate(case, T_END)  # compiles
            walls = []
            for _ in range(REPEATS):
                t0 = time.perf_counter()
                res = transient.simulate(case, T_END)
                walls.append(time.perf_counter() - t0)
            wall = min(walls)
            row = dict(variant=name, rtol=rtol, steps=int(res.meta["steps"]), wall_per_simulated_s=wall / T_END,
                       real_time_factor=T_END / wall, error=_common.transient_error(res, ref, ERROR_CHANNELS), reference_steps=int(ref.meta["steps"]))
            rows.append(row)
            print(f"{name:<50} {rtol:>7.0e} {row['steps']:>7} {wall / T_END:>13.3f}s {T_END / wall:>12.1f}x "
                  f"{row['error']:>9.1e}", flush=True)
    out = ROOT / "benchmarks" / "results" / "components_accuracy.json"
    out.write_text(json.dumps(dict(machine=info, t_end_s=T_END, rtol_reference=RTOL_REF, channels=ERROR_CHANNELS,
                                   rows=rows), indent=1))
    print(f"wrote {out.relative_to(ROOT)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--accuracy", action="store_true", help="the accuracy-time rows instead of the cost table")
    args = ap.parse_args()
    info = _common.machine_info()
    if args.accuracy:
        print(_common.machine_line(info), flush=True)
        return accuracy(info)
    print(_common.machine_line(info), flush=True)
    rows = []
    print(f"{'variant':<50} {'coords':>6} {'steps':>7} {'wall / sim. s':>14} {'vs real time':>13} {'first call':>11}")
    for name, text in variants().items():
        sc = loads_scene(text)
        t0 = time.perf_counter()
        transient.simulate(sc, T_END)
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = transient.simulate(sc, T_END)
        wall = time.perf_counter() - t0
        row = dict(variant=name, coordinates=drive.n_independent(sc), steps=int(res.meta["steps"]),
                   wall_per_simulated_s=wall / T_END, real_time_factor=T_END / wall, first_call_s=first)
        rows.append(row)
        print(f"{name:<50} {row['coordinates']:>6} {row['steps']:>7} {wall / T_END:>13.3f}s "
              f"{T_END / wall:>12.1f}x {first:>10.1f}s", flush=True)
    out = ROOT / "benchmarks" / "results" / "components.json"
    out.write_text(json.dumps(dict(machine=info, t_end_s=T_END, rows=rows), indent=1))
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
