"""The ``beltjax`` command.

Every failure caused by the input ends with one line on stderr naming the
argument or the cause, and a non-zero exit status; no tracebacks (set
``BELTJAX_DEBUG=1`` to see them).
"""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import sys

from beltjax.errors import BeltjaxError, InputError, printable
from beltjax.summaries import (_panels_note, campbell_summary, modal_table, simulation_table, span_table,  # noqa: F401
                               statics_table)
from beltjax.drive.effects import effects_of
from beltjax import outputs


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse's default prints the usage too)
        raise InputError(message)


def _number(name, positive=False, allow_zero=True, finite=True):
    """A number argument; finite=False leaves NaN and infinity to the API's range check."""
    def parse(text):
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"--{name} must be a number, got {text!r}") from None
        if finite and not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"--{name} must be finite, got {text!r}")
        if positive and (x < 0 or (x == 0 and not allow_zero)):
            raise argparse.ArgumentTypeError(f"--{name} must be {'> 0' if not allow_zero else '>= 0'}, got {text!r}")
        return x

    return parse


def _count(name):
    """A whole-number argument (its range is the API's to check)."""
    def parse(text):
        try:
            return int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"--{name} must be a whole number, got {text!r}") from None

    return parse


def _elements(text):
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--elements must be an integer, got {text!r}") from None
    if n < 2:
        raise argparse.ArgumentTypeError(f"--elements must be at least 2, got {n}")
    if n > 400:
        raise argparse.ArgumentTypeError(f"--elements must be at most 400, got {n}")
    return n

def _fraction(text):
    x = _number("settle")(text)
    if not 0.0 <= x < 1.0:
        raise argparse.ArgumentTypeError(f"--settle must lie in [0, 1), got {text!r}")
    return x


MAX_SPEEDS = 2000  # most speeds in one Campbell sweep


def _rpm_range(text):
    """--rpm A:B:STEP -> the speeds from A by STEP and B itself (:func:`beltjax.validate.rpm_range`)."""
    from beltjax.validate import rpm_range

    parts = text.split(":")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"--rpm must be A:B:STEP (three numbers, e.g. 0:2500:50), got {text!r}")
    try:
        a, b, step = (float(x) for x in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--rpm must be A:B:STEP with numbers, got {text!r}") from None
    try:
        return rpm_range(a, b, step, MAX_SPEEDS)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--rpm {exc}, got {text!r}") from None


def _orders(text):
    """--orders 1,2,3 -> tuple of positive floats."""
    out = []
    for x in (x.strip() for x in text.split(",")):
        try:
            k = float(x)
        except ValueError:
            raise argparse.ArgumentTypeError(f"--orders must be comma-separated numbers, got {text!r}") from None
        if not math.isfinite(k) or k <= 0:
            raise argparse.ArgumentTypeError(f"--orders must be positive and finite, got {x!r} in {text!r}")
        out.append(k)
    return tuple(out)


def _modes(text):
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--modes must be a positive integer, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"--modes must be at least 1, got {n}")
    return n


def cmd_span(args) -> int:
    """Run the span analysis, print the table, write span.json and span_modes.png."""
    from beltjax import analyse_span
    from beltjax.plotting import plot_span_modes
    from beltjax.span import check_arguments

    check_arguments(args.length, args.tension, args.EA, args.EI, args.rhoA, args.speed, args.elements, args.bc,
                    args.bending, keys={k: f"--{k}" for k in ("length", "tension", "EA", "EI", "rhoA", "speed")})
    out = _out_dir(args.out)
    result = analyse_span(args.length, args.tension, args.EA, args.EI, args.rhoA, speed=args.speed,
                          n_elements=args.elements, bc=args.bc, bending=args.bending)
    data = result.to_json()
    for f in data["frequencies_hz"]:
        if not math.isfinite(f):
            raise RuntimeError("the eigen-analysis produced a non-finite frequency")
    outputs.write_json(out / "span.json", data)
    plot_span_modes(result, out / "span_modes.png")
    print(span_table(result))
    return 0


# --------------------------------------------------------------------------- drive commands


def _out_dir(text) -> pathlib.Path:
    """The folder a command writes its files into: the temporary folder of the output stage
    that :func:`main` opened for ``--out`` (moved into ``--out`` when the command succeeds,
    see :mod:`beltjax.outputs`); called outside main, ``text`` itself, created."""
    from beltjax import outputs

    stage = outputs.active()
    if stage is not None and str(stage.target) == str(text):
        return stage.folder()
    out = pathlib.Path(text)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot create directory {str(out)!r}: {exc.strerror}") from None
    return out


def _load(path):
    """Load a scene file; a bad one is an InputError naming the file and the key."""
    from beltjax.scene import SceneError, load_scene

    try:
        return load_scene(path)
    except SceneError as exc:
        msg = str(exc)
        raise InputError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from None


def _analysis(fn, *args, **kwargs):
    """Run an analysis; a drive without an admissible static state is an InputError."""
    from beltjax.statics import StaticsError

    try:
        return fn(*args, **kwargs)
    except StaticsError as exc:
        raise InputError(str(exc)) from None


def _title(scene, path) -> str:
    return f"{scene.description} ({path})" if scene.description else str(path)


def cmd_statics(args) -> int:
    """Static state of a drive: statics.json, layout.png and a table."""
    from beltjax import statics
    from beltjax.plotting import plot_layout

    scene = _load(args.scene)
    out = _out_dir(args.out)
    res = _analysis(statics.analyse_statics, scene, loaded=False if args.unloaded else None)
    data = res.to_json()
    if not all(math.isfinite(x) for x in data["span_tensions_N"]):
        raise RuntimeError("the statics produced a non-finite span tension")
    outputs.write_json(out / "statics.json", data)
    plot_layout(scene, res, out / "layout.png")
    print(f"statics of {_title(scene, args.scene)}")
    print(statics_table(res))
    for warning in res.warnings:  # arcs that would slip, the arm on a stop
        print(f"beltjax: warning: {warning}", file=sys.stderr)
    return 0


def cmd_modal(args) -> int:
    """Natural frequencies and mode shapes of a drive: modal.json, modes.png and a table."""
    from beltjax import drive, drive_modal
    from beltjax.plotting import plot_drive_modes

    scene = _load(args.scene)
    out = _out_dir(args.out)
    speed = None if args.rpm is None else float(drive.belt_speed(scene, args.rpm))
    m = _analysis(drive_modal.analyse_modes, scene, speed)
    data = m.to_json(n_modes=args.modes)
    if not all(math.isfinite(x) for x in data["frequencies_hz"]):
        raise RuntimeError("the eigen-analysis produced a non-finite frequency")
    outputs.write_json(out / "modal.json", data)
    plot_drive_modes(scene, m, out / "modes.png", n_modes=args.modes, pool=args.modes)
    rpm = "" if args.rpm is None else f" ({args.rpm:g} rpm of the drive pulley)"
    print(f"modes of {_title(scene, args.scene)}")
    print(f"belt speed {m.speed_m_s:g} m/s{rpm}" + ("; stable" if m.stable else ""))
    if m.speed_m_s != 0 and not effects_of(scene).moving_belt:
        print("note: the scene does not list the \"transport\" effect, so the belt speed does not change the modes")
    print(modal_table(m, args.modes))
    print(_panels_note(m, args.modes))
    for warning in [m.statics.length_note] if m.statics.length_note else []:  # spans off their free length
        print(f"beltjax: warning: {warning}", file=sys.stderr)
    return 0


def cmd_campbell(args) -> int:
    """Campbell diagram of a drive: campbell.json, campbell.png and the crossings."""
    from beltjax import campbell
    from beltjax.plotting import plot_campbell
    from beltjax.progress import counter

    scene = _load(args.scene)
    out = _out_dir(args.out)
    progress = counter("campbell", "speeds", with_bar=False)

    c = _analysis(campbell.analyse_campbell, scene, args.rpm, orders=args.orders, n_modes=args.modes,
                  progress=progress)
    outputs.write_json(out / "campbell.json", c.to_json())
    plot_campbell(c, out / "campbell.png", title=_title(scene, args.scene))
    print(f"Campbell diagram of {_title(scene, args.scene)}")
    print(campbell_summary(c))
    return 0


def cmd_simulate(args) -> int:
    """Transient of a drive: simulation.npz, simulation.json, time-history and spectrum plots."""
    from beltjax import progress, transient
    from beltjax.plotting import plot_simulation, plot_spectra

    scene = _load(args.scene)
    kept = args.t_end * (1 - args.settle) / (args.output_dt or transient.default_output_dt(scene))
    if args.settle > 0 and kept < 16:  # (before the run) a summary of a few samples says nothing
        raise InputError(f"--settle: {args.settle:g} leaves {int(kept)} output samples to summarise, fewer than 16")
    out = _out_dir(args.out)
    failed = None
    try:
        res = _analysis(transient.simulate, scene, args.t_end, dt=args.dt, output_dt=args.output_dt,
                        progress=True)
    except transient.TransientError as exc:
        if getattr(exc, "partial", None) is None:
            raise InputError(str(exc)) from None
        res, failed = exc.partial, str(exc)  # the solver failed: its outputs up to there are written
    summary = res.summary(settle_fraction=args.settle)
    summary["scene"] = str(args.scene)
    if failed:
        summary["failure"] = failed
    res.save_npz(out / "simulation.npz")
    outputs.write_json(out / "simulation.json", summary)
    title = _title(scene, args.scene)
    plot_simulation(res.t, res.channels, res.columns, transient.UNITS, out / "simulation.png", title=title)
    plot_spectra(res.t, res.channels, res.columns, transient.UNITS, out / "spectra.png", title=title,
                 settle_fraction=args.settle)
    print(f"transient of {title}")
    print(simulation_table(res, summary))
    for line in transient.run_warnings(res.meta):  # slack spans, spans past the critical speed, forcing
        print(line)
    if failed:
        progress.message(f"beltjax: error: {failed}")
        return 1
    return 0


def cmd_orders(args) -> int:
    """Response over engine speed: orders.json, orders.csv, orders.npz, figures, a summary."""
    from beltjax import orders
    from beltjax.orders import command
    from beltjax.progress import counter

    scene = _load(args.scene)
    out = _out_dir(args.out)
    settings = orders.Settings(samples=args.samples, max_order=args.max_order, method=args.method)
    try:
        res = _analysis(orders.response_over_speed, scene, args.rpm, settle_s=args.settle_s, settings=settings,
                        progress=counter("  orders", "speeds"))
    except orders.OrdersError as exc:
        raise InputError(str(exc)) from None
    title = _title(scene, args.scene)
    command.write(res, out, title)
    print(f"response over speed of {title}")
    print(command.summary(res))
    return 0


# --------------------------------------------------------------------------- fit, sweep, optimize


def cmd_fit(args) -> int:
    """Identification: fit.json, a scene block with the fitted parameters, plots."""
    from identification import fit
    from identification.data import DataError

    out = _out_dir(args.out)
    try:
        return _analysis(fit.run, pathlib.Path(args.data), out)
    except DataError as exc:
        raise InputError(str(exc)) from None


def cmd_sweep(args) -> int:
    """Batched parametric sweep: sweep.csv, sweep.json, plots."""
    from beltjax import sweep
    from beltjax.parameters import ParameterError

    scene = _load(args.scene)
    out = _out_dir(args.out)
    try:
        return _analysis(sweep.run, scene, pathlib.Path(args.spec), out, backend=args.backend)
    except (sweep.SweepError, ParameterError) as exc:
        raise InputError(str(exc)) from None


def cmd_optimize(args) -> int:
    """Gradient-based layout optimisation: optimize.json, the optimised scene, before/after plots."""
    from beltjax import optimize
    from beltjax.parameters import ParameterError

    scene = _load(args.scene)
    out = _out_dir(args.out)
    try:
        return _analysis(optimize.run, scene, pathlib.Path(args.spec), out, scene_path=pathlib.Path(args.scene))
    except (optimize.OptimizeError, ParameterError) as exc:
        raise InputError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="beltjax", description="Belt-drive simulation with ANCF belt spans (JAX).")
    sub = p.add_subparsers(dest="command", parser_class=_Parser)
    sp = sub.add_parser("span", help="natural frequencies and modes of one tensioned (moving) belt span")
    # finiteness and ranges: beltjax.span.check_arguments in cmd_span (the API's messages)
    sp.add_argument("--length", type=_number("length", True, False, False), required=True, help="span length [m]")
    sp.add_argument("--tension", type=_number("tension", True, False, False), required=True, help="static tension [N]")
    sp.add_argument("--speed", type=_number("speed", finite=False), default=0.0, help="belt speed [m/s] (default 0)")
    sp.add_argument("--EA", type=_number("EA", True, False, False), required=True, help="axial stiffness [N]")
    sp.add_argument("--EI", type=_number("EI", True, False, False), required=True, help="bending stiffness [N m^2]")
    sp.add_argument("--rhoA", type=_number("rhoA", True, False, False), required=True,
                    help="mass per unit unstretched length [kg/m]")
    sp.add_argument("--elements", type=_elements, default=16, help="ANCF elements (default 16)")
    sp.add_argument("--bc", choices=["pinned", "clamped"], default="pinned", help="end condition (default pinned)")
    sp.add_argument("--bending", choices=["linear", "exact"], default="linear",
                    help="bending energy: thesis' small-strain form or exact curvature")
    sp.add_argument("--out", default="out", help="output directory (default ./out)")
    sp.set_defaults(func=cmd_span)

    st = sub.add_parser("statics", help="static state of a drive: span tensions, hub forces, tensioner angle")
    st.add_argument("scene", help="scene file (TOML)")
    st.add_argument("--out", default="out", help="output directory (default ./out)")
    st.add_argument("--unloaded", action="store_true",
                    help="the unloaded state only (default: the operating point under the scene's mean loads, "
                         "with the unloaded state beside it)")
    st.set_defaults(func=cmd_statics)

    mo = sub.add_parser("modal", help="natural frequencies and mode shapes of a drive")
    mo.add_argument("scene", help="scene file (TOML)")
    mo.add_argument("--modes", type=_modes, default=20,
                    help="modes reported in the table and modal.json, and drawn in modes.png (its flexible ones, "
                         "at most 24) (default 20)")
    mo.add_argument("--rpm", type=_number("rpm", True), default=None,
                    help="drive pulley speed [rpm] (default: the scene's speed_rpm)")
    mo.add_argument("--out", default="out", help="output directory (default ./out)")
    mo.set_defaults(func=cmd_modal)

    ca = sub.add_parser("campbell", help="Campbell diagram: frequencies against drive pulley speed")
    ca.add_argument("scene", help="scene file (TOML)")
    ca.add_argument("--rpm", type=_rpm_range, required=True,
                    help="drive pulley speeds A:B:STEP [rpm]: from A by STEP, and B itself (e.g. 0:2500:50)")
    ca.add_argument("--orders", type=_orders, default=(1.0, 2.0, 3.0),
                    help="excitation orders, comma-separated (default 1,2,3)")
    ca.add_argument("--modes", type=_modes, default=20, help="lowest modes computed (default 20)")
    ca.add_argument("--out", default="out", help="output directory (default ./out)")
    ca.set_defaults(func=cmd_campbell)

    si = sub.add_parser("simulate", help="transient of a drive (time histories, spectra)")
    si.add_argument("scene", help="scene file (TOML)")
    si.add_argument("--t-end", dest="t_end", type=_number("t-end", True, False), required=True,
                    help="simulated time [s] (at most 20 million time steps)")
    si.add_argument("--dt", type=_number("dt", True, False), default=None,
                    help="time step [s] (default: the scene's [simulation] dt_s, else 1e-4); a fixed step must "
                         "sample every forcing frequency more than twice a period (a warning below 20 times)")
    si.add_argument("--output-dt", dest="output_dt", type=_number("output-dt", True, False), default=None,
                    help="output interval [s] (default 5e-4 hybrid, 1e-3 rotational); not below a fixed step, "
                         "and below half the period of every forcing")
    si.add_argument("--settle", type=_fraction, default=0.0,
                    help="fraction of the run left out of the summary and spectra (start-up), default 0")
    si.add_argument("--out", default="out", help="output directory (default ./out)")
    si.set_defaults(func=cmd_simulate)

    od = sub.add_parser("orders", help="response over engine speed: periodic steady state at each speed "
                                       "(arm motion, span tensions, hub loads, slip margins, order content)")
    od.add_argument("scene", help="scene file (TOML)")
    od.add_argument("--rpm", type=_rpm_range, required=True,
                    help="drive pulley speeds A:B:STEP [rpm]: from A by STEP, and B itself; all > 0 (e.g. 600:6000:50)")
    od.add_argument("--method", default="shooting",  # checked by beltjax.orders (its METHODS)
                    help="shooting or settle: periodic steady state by shooting (Newton on the one-cycle map; "
                         "default; belt_slip and the hybrid model settle) or by a settling transient")
    od.add_argument("--settle-s", dest="settle_s", type=_number("settle-s", True), default=1.0,
                    help="transient time before the recorded cycle [s] of the settling method and of the speeds "
                         "the shooting did not converge at (default 1; speeds that have not settled run again 4x "
                         "longer, then are flagged)")
    od.add_argument("--max-order", dest="max_order", type=_number("max-order", True, False), default=8.0,
                    help="highest crank order reported (default 8)")
    od.add_argument("--samples", type=_count("samples"), default=128,
                    help="output samples per excitation cycle (default 128)")
    od.add_argument("--out", default="out", help="output directory (default ./out)")
    od.set_defaults(func=cmd_orders)

    fi = sub.add_parser("fit", help="fit belt and tensioner parameters to bench data (identification)")
    fi.add_argument("data", help="dataset file (TOML) pointing at CSV files")
    fi.add_argument("--out", default="out", help="output directory (default ./out)")
    fi.set_defaults(func=cmd_fit)

    sw = sub.add_parser("sweep", help="batched parametric sweep (grid, random, tolerance study)")
    sw.add_argument("scene", help="scene file (TOML)")
    sw.add_argument("spec", help="sweep file (TOML)")
    sw.add_argument("--backend", choices=["local", "dask"], default="local",
                    help="where the batch runs: this process (vmap, sharded over local devices) or a Dask cluster")
    sw.add_argument("--out", default="out", help="output directory (default ./out)")
    sw.set_defaults(func=cmd_sweep)

    op = sub.add_parser("optimize", help="gradient-based layout optimisation of a drive")
    op.add_argument("scene", help="scene file (TOML)")
    op.add_argument("spec", help="optimisation file (TOML)")
    op.add_argument("--out", default="out", help="output directory (default ./out)")
    op.set_defaults(func=cmd_optimize)
    return p


def main(argv=None) -> int:
    """Entry point of the ``beltjax`` command; returns the exit status.

    A command writes its files into a temporary folder next to ``--out``, moved into ``--out`` only
    when it has finished without an error (:mod:`beltjax.outputs`; ``wrote ...`` lists them); a
    failing command leaves ``--out`` as it was.  An error ends an open progress line first.
    """
    from beltjax import progress, runtime

    runtime.configure()  # before the first JAX computation (a no-op when called in a running process)
    debug = os.environ.get("BELTJAX_DEBUG") == "1"
    try:
        args = build_parser().parse_args(argv)
        if args.command is None:
            raise InputError("a command is required: span, statics, modal, campbell, simulate, orders, fit, sweep or optimize")
        for name in ("scene", "spec", "data", "out"):
            if getattr(args, name, None) == "":
                raise InputError("--out: empty directory name" if name == "out" else f"argument {name}: empty file name")
        runtime.enable_compile_cache()
        with runtime.sigterm_as_exit(), outputs.staged(args.out) as stage:
            code = args.func(args)
        progress.end_line()
        if stage.written:
            print(outputs.written_line(stage.written), flush=True)
        return code
    except BeltjaxError as exc:
        progress.message(f"beltjax: error: {printable(str(exc))}")
        return 2
    except KeyboardInterrupt:
        progress.message("beltjax: interrupted")
        return 130
    except Exception as exc:  # never a traceback for the user
        progress.end_line()
        if debug:
            raise
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        progress.message(f"beltjax: error: {printable(msg)}")
        return 1


if __name__ == "__main__":
    sys.exit(main())

