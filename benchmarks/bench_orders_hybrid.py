"""Responses over engine speed with the hybrid model (``beltjax orders`` of an ``ancf`` scene): what
a speed costs and how the hybrid response compares with the rotational one, on the eight-pulley
drive.

Run: ``python benchmarks/bench_orders_hybrid.py`` (about 10 min on a 2-core CPU); writes
``benchmarks/results/orders_hybrid.json``.  ``--elements 4,8`` (elements per span), ``--rpm
700:1100:200`` (speeds, end included), ``--settle-s 0.5``; ``--vmap-check`` (about 10 min) only
times one speed without vmap against a vmapped batch of one (``results/orders_hybrid_vmap.json``);
``--batch-check 8,64 --name gpu/orders_hybrid_batch`` (meant for a GPU) times one speed at a time
against vmapped batches of those sizes, the same speeds (``results/<name>.json``).

Each mesh: ``scenes/fead_8pulley.toml`` with ``fidelity = "ancf"``; the settling transient with the
hybrid model's generalized-alpha (step at most 1e-4 s, shortened to whole steps per sample: 128
samples per crank revolution), started on the linearised drive's periodic response; speeds that
had not settled run again 4x longer.  The first call compiles; the second call is timed.  The
rotational model runs the same speeds by its default shooting.  Compared over the speeds both
call ``ok``: the mean span tensions (the operating point, which both fidelities share), the
arm's and the spans' peak to peak (the dynamics, where the belt's span mass and transverse
motion enter the hybrid model only).  Peak memory is the process's (compilation included).
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy/jax)

import argparse
import dataclasses
import resource
import time
from pathlib import Path

import jax
import numpy as np

from beltjax import orders
from beltjax.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "fead_8pulley.toml"


def _speeds(text: str) -> np.ndarray:
    a, b, step = (float(x) for x in text.split(":"))
    return np.arange(a, b + 0.5 * step, step)


def _timed(sc, rpm, settle_s, label):
    start = time.perf_counter()

    def progress(done, total):
        print(f"    {label}: {time.perf_counter() - start:7.1f} s, {done}/{total} speeds of a pass", flush=True)

    t0 = time.perf_counter()
    orders.response_over_speed(sc, rpm, settle_s=settle_s, progress=progress)
    first = time.perf_counter() - t0
    start = time.perf_counter()
    r = orders.response_over_speed(sc, rpm, settle_s=settle_s, progress=progress)
    return r, first, time.perf_counter() - start


def vmap_check(info) -> None:
    """One speed run without vmap (the default for batches of one) against a vmapped batch of one:
    the hybrid model at 4 elements per span (800 rpm) and the rotational shooting (30 speeds);
    second calls timed; writes results/orders_hybrid_vmap.json."""
    from beltjax.orders import run as R

    base = load_scene(SCENE)
    hybrid = dataclasses.replace(base, model=dataclasses.replace(base.model, fidelity="ancf", elements_per_span=4))
    orig, rows = R._batch, []
    for label, sc, rpm, settle in (("hybrid, 4 el./span", hybrid, [800.0], 0.5),
                                   ("rotational shooting", base, np.linspace(600.0, 6000.0, 30), 1.0)):
        got = {}
        for mode in ("single", "vmapped batch of one"):
            R._batch = orig if mode == "single" else (lambda s, k, single=False: orig(s, k, False))
            for call in ("first", "timed"):
                t0 = time.perf_counter()
                r = orders.response_over_speed(sc, rpm, settle_s=settle)
                got[mode, call] = time.perf_counter() - t0
            got[mode] = r
        R._batch = orig
        a, b = got["single"], got["vmapped batch of one"]
        diff = float(np.max(np.abs(a.channel("arm_angle_deg", "p2p") - b.channel("arm_angle_deg", "p2p"))))
        rows.append(dict(case=label, speeds=len(rpm), single_s=got["single", "timed"],
                         vmapped_s=got["vmapped batch of one", "timed"], arm_p2p_difference_deg=diff))
        print(f"{label}: {len(rpm)} speeds, without vmap {got['single', 'timed']:.2f} s, vmapped batch of one "
              f"{got['vmapped batch of one', 'timed']:.2f} s, arm p2p difference {diff:.1e} deg", flush=True)
    print(f"wrote {_common.save_json('orders_hybrid_vmap', dict(machine=info, rows=rows))}")


def batch_check(info, sizes: list[int], name: str, settle_s: float) -> None:
    """The hybrid model at 4 elements per span: speeds one at a time (what ``beltjax orders`` runs)
    against one vmapped batch of each size (at least 2) in ``sizes`` over 700-1000 rpm (where every speed is
    ``ok``), compiled ahead and timed once each, the arm's peak to peak compared with the one-by-one runs.  On a
    CPU a vmapped batch forms the implicit step's Jacobian at every step (:func:`vmap_check`); on a
    GPU that cost may be shared by the batch.  Writes results/<name>.json."""
    from beltjax import drive
    from beltjax.orders import run as R
    from beltjax.orders import steady

    base = load_scene(SCENE)
    sc = drive.canonical(dataclasses.replace(base, model=dataclasses.replace(base.model, fidelity="ancf",
                                                                               elements_per_span=4)))
    settings = dataclasses.replace(steady.for_scene(sc, None), gradients=False)
    rows, one_by_one = [], {}
    for b in sizes:
        rpm = np.linspace(700.0, 1000.0, b)
        settings_b = dataclasses.replace(settings, max_steps=max(settings.max_steps, R.fixed_steps(settings, rpm, settle_s)))
        fn = R._batch(settings_b, (), False)
        args = (sc, jax.numpy.zeros((b, 0)), jax.numpy.asarray(rpm), jax.numpy.full(b, settle_s))
        t0 = time.perf_counter()
        fn = fn.lower(*args).compile()
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        timed = time.perf_counter() - t0
        arm = np.asarray(out["arm_angle_deg:p2p"])
        row = dict(batch=b, compile_s=first, timed_s=timed, speeds_per_s=b / timed,
                   steps=np.asarray(out["steps"]).astype(int).tolist(), settling=np.asarray(out["settling"]).tolist())
        print(f"vmapped batch of {b}: compile {first:.1f} s, timed {timed:.2f} s = {b / timed:.3f} speeds/s", flush=True)
        if not one_by_one:  # one speed at a time: the batch's end speeds (in every batch), second calls timed
            single = R._batch(settings_b, (), True)
            for i in (0, b - 1):
                one = (sc,) + tuple(a[i : i + 1] for a in args[1:])
                if not i:
                    single = single.lower(*one).compile()
                t0 = time.perf_counter()
                got = jax.block_until_ready(single(*one))
                one_by_one[i > 0] = (time.perf_counter() - t0, float(np.asarray(got["arm_angle_deg:p2p"])[0]))
            per = float(np.mean([v[0] for v in one_by_one.values()]))
            print(f"one at a time: {per:.2f} s per speed = {1 / per:.3f} speeds/s", flush=True)
        row["arm_p2p_difference_deg"] = max(abs(arm[0] - one_by_one[False][1]), abs(arm[-1] - one_by_one[True][1]))
        rows.append(row)
    per = float(np.mean([v[0] for v in one_by_one.values()]))
    for row in rows:
        row["throughput_against_one_at_a_time"] = row["speeds_per_s"] * per
        print(f"batch {row['batch']}: {row['throughput_against_one_at_a_time']:.2f}x one at a time", flush=True)
    out = _common.save_json(name, dict(backend=jax.default_backend(), settle_s=settle_s, one_at_a_time_s=per,
                                       one_by_one={"700 rpm": one_by_one[False], "1000 rpm": one_by_one[True]}, rows=rows))
    print(f"wrote {out}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--elements", default="4,8")
    ap.add_argument("--rpm", default="700:1100:200")
    ap.add_argument("--settle-s", dest="settle_s", type=float, default=0.5)
    ap.add_argument("--vmap-check", action="store_true", help="only: one speed without vmap against a vmapped one")
    ap.add_argument("--batch-check", dest="batch_check", default=None, help="only: vmapped batches of these sizes")
    ap.add_argument("--name", default="orders_hybrid_batch", help="results/<name>.json of --batch-check")
    args = ap.parse_args()
    info = _common.machine_info()
    print(_common.machine_line(info), flush=True)
    if args.vmap_check:
        return vmap_check(info)
    if args.batch_check:
        return batch_check(info, [int(b) for b in args.batch_check.split(",")], args.name, args.settle_s)
    rpm = _speeds(args.rpm)
    base = load_scene(SCENE)
    rot, rot_first, rot_wall = _timed(base, rpm, args.settle_s, "rotational")
    print(f"rotational: first call {rot_first:.1f} s, timed {rot_wall:.2f} s, status {rot.status}", flush=True)
    rows = []
    head = (f"{'el./span':>8} {'coords':>6} {'speeds':>6} {'first call':>10} {'timed':>8} {'per speed':>9} "
            f"{'steps':>13} {'rerun':>5} {'status':<28} {'mean T diff':>11} {'arm p2p h/r':>16} {'span p2p h/r':>16}")
    print(head)
    for n_el in (int(x) for x in args.elements.split(",")):
        sc = dataclasses.replace(base, model=dataclasses.replace(base.model, fidelity="ancf", elements_per_span=n_el))
        r, first, wall = _timed(sc, rpm, args.settle_s, f"{n_el} el./span")
        ok = (np.asarray(r.status) == "ok") & (np.asarray(rot.status) == "ok")
        row = dict(elements_per_span=n_el, speeds=len(rpm), first_call_s=first, wall_s=wall,
                   per_speed_s=wall / len(rpm), steps=list(map(int, r.meta["steps"])), rerun=r.meta["rerun_speeds"],
                   status=r.status, settling=[float(x) for x in r.settling], rotational_status=rot.status,
                   peak_rss_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
                   compared=int(ok.sum()))
        cols = ("", "", "")
        if ok.any():
            t_h, t_r = r.channel("span_tensions_N", "mean")[ok], rot.channel("span_tensions_N", "mean")[ok]
            row["max_mean_tension_difference"] = float(np.max(np.abs(t_h - t_r) / np.abs(t_r)))
            a_h, a_r = r.channel("arm_angle_deg", "p2p")[ok], rot.channel("arm_angle_deg", "p2p")[ok]
            s_h = np.max(r.channel("span_tensions_N", "p2p")[ok], axis=1)
            s_r = np.max(rot.channel("span_tensions_N", "p2p")[ok], axis=1)
            row.update(arm_p2p_hybrid_deg=a_h.tolist(), arm_p2p_rotational_deg=a_r.tolist(),
                       span_p2p_hybrid_N=s_h.tolist(), span_p2p_rotational_N=s_r.tolist(),
                       speeds_compared=rpm[ok].tolist())
            cols = (f"{row['max_mean_tension_difference']:.1e}",
                    f"{float(np.min(a_h / a_r)):.3f}-{float(np.max(a_h / a_r)):.3f}",
                    f"{float(np.min(s_h / s_r)):.3f}-{float(np.max(s_h / s_r)):.3f}")
        node = r.channel("node_displacements_m", "p2p")
        row["mid_span_p2p_max_mm"] = (np.max(node, axis=1) * 1e3).tolist()
        rows.append(row)
        print(f"{n_el:>8} {r.meta.get('coordinates', ''):>6} {len(rpm):>6} {first:>9.1f}s {wall:>7.1f}s "
              f"{wall / len(rpm):>8.1f}s {min(row['steps']):>6}-{max(row['steps']):<6} {row['rerun']:>5} "
              f"{','.join(r.status):<28} {cols[0]:>11} {cols[1]:>16} {cols[2]:>16}", flush=True)
    out = _common.save_json("orders_hybrid", dict(machine=info, backend=jax.default_backend(), scene=SCENE.name,
                                                  rpm=rpm.tolist(), settle_s=args.settle_s,
                                                  rotational=dict(first_call_s=rot_first, wall_s=rot_wall,
                                                                  status=rot.status),
                                                  rows=rows))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
