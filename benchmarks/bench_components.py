"""What each FEAD component costs a transient: the eight-pulley drive at idle, rotational model,
with one component changed at a time.

Run: ``python benchmarks/bench_components.py`` (about 3 min); writes
``benchmarks/results/components.json``.

Each variant runs 1 s of idle (Dopri8, rtol 1e-6, the default) twice: the first call compiles,
the second is timed.  Variants: the scene as shipped (2nd and 4th crank orders, viscous
tensioner), one crank harmonic instead of the orders, the dry-friction tensioner with stops
(scenes/fead_8pulley_friction.toml), the alternator decoupler (scenes/fead_8pulley_decoupler.toml)
and a crank isolator (400 N m/rad, 0.3 N m s/rad).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

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


def main():
    info = _common.machine_info()
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
