"""The optimised scene file: the scene's text with the optimised values written in (comments and
layout kept), or, where that text cannot be edited, the whole scene written anew."""

from __future__ import annotations

import re
import tomllib

import numpy as np

from beltjax import parameters
from beltjax import textfile
from beltjax.scene import Scene, SceneError, loads_scene
from beltjax.scene.write import dumps_scene, first_difference
from beltjax.optimize.problem import OptimizeError


def _fmt(v: float) -> str:
    return repr(float(v))


_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.]+)\s*\]\]?\s*(#.*)?$")


def _blocks(lines: list[str]) -> list[tuple[str, int, int]]:
    """(table name, first line, end line) of each TOML table; array tables named 'pulley#<name>'."""
    heads = [(i, _HEADER.match(ln)) for i, ln in enumerate(lines)]
    heads = [(i, m) for i, m in heads if m]
    out = []
    for k, (i, m) in enumerate(heads):
        end = heads[k + 1][0] if k + 1 < len(heads) else len(lines)
        name = m.group(2)
        if m.group(1) == "[[" and name == "pulley":
            nm = next((re.match(r'^\s*name\s*=\s*"([^"]*)"', ln) for ln in lines[i + 1:end]
                       if re.match(r'^\s*name\s*=', ln)), None)
            name = f"pulley#{nm.group(1) if nm else ''}"
        out.append((name, i, end))
    return out


def _set_key(lines, block, key, component, value) -> bool:
    """Replace ``key = ...`` (or one component of ``key = [x, y]``) in ``block``; False if absent."""
    _, start, end = block
    pat = re.compile(rf"^(\s*{re.escape(key)}\s*=\s*)([^#]*?)(\s*#.*)?$")
    for i in range(start + 1, end):
        m = pat.match(lines[i])
        if not m:
            continue
        old = tomllib.loads("v = " + m.group(2))["v"]
        if component is None:
            new = _fmt(value)
        else:
            vec = list(old)
            vec[component] = float(value)
            new = "[" + ", ".join(_fmt(v) for v in vec) + "]"
        comment = m.group(3) or ""
        if "[optimised" not in comment:
            comment = (comment or "  #") + f"  [optimised; was {m.group(2).strip()}]"
        lines[i] = m.group(1) + new + comment
        return True
    return False


def edit_scene_text(text: str, scene: Scene, values: dict) -> str:
    """The scene file's text with the parameters ``values`` ({path: value}, file units) replaced.

    Keys absent from the file are inserted below their table's header; giving the belt's
    ``length`` (or ``static_tension``) comments out the other one.  Comments and layout stay.
    """
    lines = text.splitlines()
    for path, value in values.items():
        parts = path.split(".")
        component = None
        if parts[0] == "belt":
            table, key = "belt", parts[1]
        elif parts[0] == "pulley":
            table, key = f"pulley#{parts[1]}", parts[2]
            component = {"x": 0, "y": 1}[parts[3]] if len(parts) == 4 else None
        else:
            table, key = "tensioner", parts[1]
            component = {"x": 0, "y": 1}[parts[2]] if len(parts) == 3 else None
        block = next((b for b in _blocks(lines) if b[0] == table), None)
        if block is None:
            raise OptimizeError(f"no [{table.split('#')[0]}] table for {path} in the scene file", "scene")
        if key in ("length", "static_tension"):
            other = "static_tension" if key == "length" else "length"
            for i in range(block[1] + 1, block[2]):
                if re.match(rf"^\s*{other}\s*=", lines[i]):
                    lines[i] = f"# {lines[i].strip()}   (replaced by the optimised {key})"
        if not _set_key(lines, block, key, component, value):
            if component is not None:
                vec = np.asarray(parameters.get_value(scene, path.rsplit(".", 1)[0] + ".x")), \
                    np.asarray(parameters.get_value(scene, path.rsplit(".", 1)[0] + ".y"))
                vec = [float(vec[0]), float(vec[1])]
                vec[component] = float(value)
                new = f"{key} = [{_fmt(vec[0])}, {_fmt(vec[1])}]"
            else:
                new = f"{key} = {_fmt(value)}"
            lines.insert(block[1] + 1, new + "   # set by beltjax optimize")
    return "\n".join(lines) + "\n"


def _verify_scene_text(text: str, original: Scene, values: dict) -> None:
    """Raise OptimizeError unless ``text`` parses to ``original`` with exactly ``values`` changed
    (bit for bit: :func:`beltjax.scene.write.first_difference`)."""
    try:
        new = loads_scene(text, source="optimized_scene.toml")
    except SceneError as exc:
        raise OptimizeError(f"the optimised scene does not parse: {exc}", "optimized_scene.toml") from None
    where = first_difference(new, parameters.set_values(original, values))
    if where is not None:
        raise OptimizeError(f"the optimised scene file differs from the optimised scene at {where}",
                            "optimized_scene.toml")


def optimised_scene_text(original: Scene, values: dict, header: str, source) -> tuple[str, str | None]:
    """(text, note) of ``optimized_scene.toml``: the scene file ``source`` (a path or None) with
    ``values`` ({path: value}, file units) written in and read back to check it; where there is
    no file, or its text cannot be edited so (a layout the editor does not know: multi-line
    arrays, dotted keys, inline tables), the whole optimised scene written by
    :func:`beltjax.scene.write.dumps_scene` (read back bit for bit; no comments), with a note
    saying so.  ``header``: comment lines on top."""
    if source is not None and source.is_file():
        try:
            text = header + edit_scene_text(textfile.read_text(source, "scene"), original, values)  # no BOM
            _verify_scene_text(text, original, values)
            return text, None
        except (OptimizeError, ValueError, KeyError, IndexError, TypeError) as exc:
            why = str(exc) or type(exc).__name__
            note = (f"optimized_scene.toml written whole (the scene file's comments are not kept): its text could "
                    f"not be edited in place ({why})")
    else:
        note = "optimized_scene.toml written whole: the scene was not read from a file"
    try:
        text = dumps_scene(parameters.set_values(original, values), header.rstrip("\n").removeprefix("# "))
    except SceneError as exc:
        raise OptimizeError(f"the optimised scene cannot be written: {exc}", "optimized_scene.toml") from None
    return text, note
