"""What a lock-step batch of shootings costs: the speeds of ``beltjax orders`` run one at a time,
each Newton cycle's steps recorded, and the cost of running them all in one vmapped batch (as on
a GPU, where the batch advances in lock-step) counted in cycle steps: each Newton iteration of
the batch lasts as long as its slowest running speed's cycle.  Three rows: without the
shooting's step budget (``beltjax.orders.shooting.BUDGET_FACTOR``; the speeds where the budget
ended a cycle run again with it lifted, the others are unchanged by it) and with it, a speed
that has finished repeating its last cycle until the whole batch has (the code of 95398cd); as
shipped, with the budget and a finished speed integrating a vanishing interval
(``shooting.IDLE_FRACTION``).

Run: ``python benchmarks/bench_lockstep.py`` (the eight-pulley drive with the dry-friction
tensioner, 1000 speeds 600-6000 rpm, about 8 min on a 2-core CPU); ``--speeds N``, ``--scene``;
writes ``benchmarks/results/lockstep.json``.  Counts, not timings: they hold on any machine.
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import math
import time
from pathlib import Path

import numpy as np

from beltjax import orders
from beltjax.orders import run as orders_run
from beltjax.orders import shooting
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]


def lockstep_steps(cycles: list[list[int]], idle: bool) -> tuple[int, list[int]]:
    """(total, per iteration) of a lock-step batch's cycle steps: iteration k lasts the longest
    cycle k of any speed still iterating; a finished speed repeats its last cycle (``idle``
    False: the code before the idling, 95398cd) or integrates a vanishing interval (True)."""
    cycles = [c for c in cycles if c]
    K = max(len(c) for c in cycles)
    if idle:
        return sum(per := [max(c[k] for c in cycles if k < len(c)) for k in range(K)]), per
    return sum(per := [max(c[min(k, len(c) - 1)] for c in cycles) for k in range(K)]), per


def cycles_of(r) -> list[list[int]]:
    """Each speed's Newton cycles' steps (those run) from a response's meta."""
    return [[int(s) for s in c[:it]] for c, it in zip(r.meta["shooting_cycle_steps"], r.meta["shooting_iterations"])]


def run(sc, rpm) -> tuple[list[list[int]], orders.OrdersResult]:
    t0 = time.perf_counter()
    r = orders.response_over_speed(sc, rpm, chunk=1, settings=orders.Settings(method="shooting"),
                                   progress=lambda d, n: d % 100 == 0 and print(f"    {d}/{n} speeds, "
                                                                                f"{time.perf_counter() - t0:.0f} s",
                                                                                flush=True))
    return cycles_of(r), r


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--speeds", type=int, default=1000)
    ap.add_argument("--scene", default="fead_8pulley_friction.toml")
    args = ap.parse_args()
    info = _common.machine_info()
    print(_common.machine_line(info), flush=True)
    sc = load_scene(ROOT / "scenes" / args.scene)
    rpm = np.linspace(600.0, 6000.0, args.speeds)
    with_budget, r = run(sc, rpm)
    bound = [i for i, c in enumerate(with_budget)
             if len(c) >= 2 and max(c[1:]) >= shooting.BUDGET_FACTOR * c[0]]
    factor = shooting.BUDGET_FACTOR
    shooting.BUDGET_FACTOR = math.inf  # lifted (read when traced: a fresh program)
    orders_run._batch.cache_clear()
    without = list(with_budget)
    if bound:
        lifted, _ = run(sc, rpm[bound])
        for i, c in zip(bound, lifted):
            without[i] = c
    shooting.BUDGET_FACTOR = factor
    rows = {}
    for name, cycles, idle in (("no budget, finished speeds repeat their cycle", without, False),
                               ("budget, finished speeds repeat their cycle", with_budget, False),
                               ("budget, finished speeds idle (as shipped)", with_budget, True)):
        total, per = lockstep_steps(cycles, idle)
        worst = int(np.argmax([sum(c) for c in cycles]))
        rows[name] = dict(lockstep_cycle_steps=total, per_iteration=per, one_by_one_cycle_steps=sum(map(sum, cycles)),
                          worst_speed_rpm=float(rpm[worst]), worst_speed_cycles=cycles[worst])
        print(f"{name:<47} lock-step: {total:7d} cycle steps over {len(per)} iterations {per}; one by one "
              f"{rows[name]['one_by_one_cycle_steps']} (the most, {sum(cycles[worst])}, at {rpm[worst]:.1f} rpm)")
    shot = [c for c, m in zip(with_budget, r.meta["methods"]) if m == "shooting" and len(c) >= 2]
    ratio = max(max(c[1:]) / c[0] for c in shot) if shot else float("nan")
    print(f"where the shooting gave the result ({len(shot)} speeds with 2 or more cycles), a later cycle took at most "
          f"{ratio:.2f}x the steps of the first")
    status = {s: r.status.count(s) for s in sorted(set(r.status))}
    print(f"the budget ({factor}x the first cycle) ended a cycle at {len(bound)} speeds: "
          f"{', '.join(f'{rpm[i]:.2f}' for i in bound)} rpm; status {status}")
    out = _common.save_json("lockstep", dict(machine=info, scene=args.scene, speeds=args.speeds, rpm=[600.0, 6000.0],
                                             budget_factor=factor, largest_later_to_first=ratio, budget_bound_rpm=[float(rpm[i]) for i in bound],
                                             rows=rows, status=status))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
