"""The ``beltjax`` command.

Every failure caused by the input ends with one line on stderr naming the
argument or the cause, and a non-zero exit status; no tracebacks (set
``BELTJAX_DEBUG=1`` to see them).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import sys


class InputError(ValueError):
    """Bad input: reported as one line naming the argument or cause."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse's default prints the usage too)
        raise InputError(message)


def _number(name, positive=False, allow_zero=True):
    def parse(text):
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"--{name} must be a number, got {text!r}") from None
        if not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"--{name} must be finite, got {text!r}")
        if positive and (x < 0 or (x == 0 and not allow_zero)):
            raise argparse.ArgumentTypeError(f"--{name} must be {'> 0' if not allow_zero else '>= 0'}, got {text!r}")
        return x

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


def _enable_compile_cache():
    """JAX's persistent compilation cache for command-line runs (~/.cache/beltjax/jax)."""
    import jax

    cache = pathlib.Path(os.environ.get("BELTJAX_CACHE", pathlib.Path.home() / ".cache" / "beltjax" / "jax"))
    try:
        cache.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(cache))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # a read-only home: run without the cache
        pass


def span_table(result, n_rows: int = 12) -> str:
    """A readable table of a SpanResult (first n_rows modes plus the first longitudinal ones)."""
    import numpy as np

    r = result
    head = (f"span {r.bc[0]}-{r.bc[1]}: L = {r.length:g} m, T = {r.tension:g} N, c = {r.speed:g} m/s, "
            f"EA = {float(r.section.EA):g} N, EI = {float(r.section.EI):g} N m^2, "
            f"rhoA = {float(r.section.rhoA):g} kg/m, {r.n_elements} elements ({r.bending} bending)")
    lines = [head, f"critical speed {r.critical_speed_m_s:.2f} m/s; " + ("stable" if r.stable else "UNSTABLE")]
    if not r.stable:
        lines.append("past the critical speed the span diverges; unstable eigenvalues [1/s]:")
        lines += [f"  {lam.real:+.4g} {lam.imag:+.4g}j" for lam in r.unstable_eigenvalues]
        return "\n".join(lines)
    show_formula = r.speed == 0.0 and r.bc == ("pinned", "pinned")
    lines.append(f"{'mode':>4}  {'frequency [Hz]':>14}  {'label':<20} {'transverse share':>16}"
                 + (f"  {'beam formula [Hz]':>17}" if show_formula else ""))
    rows = list(range(min(n_rows, len(r.frequencies_hz))))
    rows += [i for i, lab in enumerate(r.labels) if lab.endswith("longitudinal")][:3]
    for i in sorted(set(rows)):
        line = f"{i + 1:>4}  {r.frequencies_hz[i]:>14.2f}  {r.labels[i]:<20} {r.transverse_share[i]:>16.3f}"
        if show_formula and r.labels[i].endswith("transverse"):
            n = int(r.labels[i].split()[0][:-2])
            EI, rhoA, L = float(r.section.EI), float(r.section.rhoA), r.length
            f = n / (2 * L) * np.sqrt((r.tension + EI * (n * np.pi / L) ** 2) * r.stretch / rhoA)
            line += f"  {f:>17.2f}"
        lines.append(line)
    lines.append(f"({len(r.frequencies_hz)} modes in all; beam formula: n/(2L) sqrt((T + EI (n pi/L)^2)/rhoA'),"
                 " rhoA' per stretched length)" if show_formula else f"({len(r.frequencies_hz)} modes in all)")
    return "\n".join(lines)


def cmd_span(args) -> int:
    """Run the span analysis, print the table, write span.json and span_modes.png."""
    from beltjax import analyse_span
    from beltjax.plotting import plot_span_modes

    out = pathlib.Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot create directory {str(out)!r}: {exc.strerror}") from None
    result = analyse_span(args.length, args.tension, args.EA, args.EI, args.rhoA, speed=args.speed,
                          n_elements=args.elements, bc=args.bc, bending=args.bending)
    data = result.to_json()
    for f in data["frequencies_hz"]:
        if not math.isfinite(f):
            raise RuntimeError("the eigen-analysis produced a non-finite frequency")
    (out / "span.json").write_text(json.dumps(data, indent=2))
    plot_span_modes(result, out / "span_modes.png")
    print(span_table(result))
    print(f"wrote {out / 'span.json'} and {out / 'span_modes.png'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="beltjax", description="Belt-drive simulation with ANCF belt spans (JAX).")
    sub = p.add_subparsers(dest="command", parser_class=_Parser)
    sp = sub.add_parser("span", help="natural frequencies and modes of one tensioned (moving) belt span")
    sp.add_argument("--length", type=_number("length", True, False), required=True, help="span length [m]")
    sp.add_argument("--tension", type=_number("tension", True, False), required=True, help="static tension [N]")
    sp.add_argument("--speed", type=_number("speed"), default=0.0, help="belt speed [m/s] (default 0)")
    sp.add_argument("--EA", type=_number("EA", True, False), required=True, help="axial stiffness [N]")
    sp.add_argument("--EI", type=_number("EI", True, False), required=True, help="bending stiffness [N m^2]")
    sp.add_argument("--rhoA", type=_number("rhoA", True, False), required=True,
                    help="mass per unit unstretched length [kg/m]")
    sp.add_argument("--elements", type=_elements, default=16, help="ANCF elements (default 16)")
    sp.add_argument("--bc", choices=["pinned", "clamped"], default="pinned", help="end condition (default pinned)")
    sp.add_argument("--bending", choices=["linear", "exact"], default="linear",
                    help="bending energy: thesis' small-strain form or exact curvature")
    sp.add_argument("--out", default="out", help="output directory (default ./out)")
    sp.set_defaults(func=cmd_span)
    return p


def main(argv=None) -> int:
    """Entry point of the ``beltjax`` command; returns the exit status."""
    debug = os.environ.get("BELTJAX_DEBUG") == "1"
    try:
        args = build_parser().parse_args(argv)
        if args.command is None:
            raise InputError("a command is required: span")
        _enable_compile_cache()
        return args.func(args)
    except InputError as exc:
        print(f"beltjax: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("beltjax: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # never a traceback for the user
        if debug:
            raise
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"beltjax: error: {msg}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
