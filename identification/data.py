"""Reading identification datasets: the one-line error, where a dataset's files may be, and the CSV
reader every fit uses."""

from __future__ import annotations

import math
import pathlib
from typing import Sequence

import numpy as np

from beltjax import textfile
from beltjax.errors import BeltjaxError
from beltjax.tomltable import show


class DataError(BeltjaxError):
    """Bad identification data: one line naming the key, file or cause."""


def dataset_file(base, name: str, key: str) -> pathlib.Path:
    """The file ``name`` (as the dataset writes it) of a dataset whose folder is ``base``.

    A dataset names only files inside its own folder: an absolute path, a path through ``..``
    and a link that resolves outside the folder are :class:`DataError` naming ``key``.
    """
    if not isinstance(name, str) or not name:
        raise DataError(f"expected a file name (relative to the dataset's folder), got {show(name)}", key)
    why = textfile.outside_problem(base, name, show(name), "the dataset's folder",
                                   "a dataset names only files inside its own folder",
                                   "a dataset names only files inside its own folder, relative to it")
    if why:
        raise DataError(why, key)
    return pathlib.Path(base).resolve() / pathlib.PurePath(name)


#: the largest magnitude a data value may have: the fits square and sum their data, and the square
#: of a number above about 1e154 overflows float64 (a value of 1e200 made a sine fit's residual NaN)
MAX_VALUE = 1e100


def read_csv(path: pathlib.Path, columns: Sequence[str], key: str, min_rows: int = 3) -> dict[str, np.ndarray]:
    """Columns of a CSV file with a header line: {name: float64 array}.

    The file is read by :func:`beltjax.textfile.read_text` (a regular file of at most 64 MiB,
    UTF-8, a byte-order mark accepted).  ``columns`` must all be present (extra columns are
    ignored); every value must be a finite number of magnitude at most :data:`MAX_VALUE`; at
    least ``min_rows`` rows.  Raises
    :class:`DataError` naming ``key`` and the file, with a line and column, never the file's text.
    """
    path = pathlib.Path(path)
    name = path.name if len(path.name) <= 60 else path.name[:40] + "..."

    def fail(_, message):
        raise DataError(f"{name}: {message}", key)

    text = textfile.read_text(path, "csv", fail)
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1)
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise DataError(f"{name} is empty", key)
    header = [h.strip() for h in lines[0][1].split(",")]
    missing = [c for c in columns if c not in header]
    if missing:
        raise DataError(f"{name} lacks column(s) {', '.join(missing)} (its header, line {lines[0][0]}, "
                             f"has {len(header)} column(s))", key)
    idx = [header.index(c) for c in columns]
    rows = []
    for n, ln in lines[1:]:
        cells = [c.strip() for c in ln.split(",")]
        if len(cells) != len(header):
            raise DataError(f"{name} line {n}: {len(cells)} values for {len(header)} columns", key)
        vals = []
        for c, i in zip(columns, idx):
            try:
                vals.append(float(cells[i]))
            except ValueError:
                raise DataError(f"{name} line {n}: not a number in column {i + 1} ({c})", key) from None
        if not all(math.isfinite(v) for v in vals):
            raise DataError(f"{name} line {n}: NaN or infinite value", key)
        big = next((j for j, v in enumerate(vals) if abs(v) > MAX_VALUE), None)
        if big is not None:
            raise DataError(f"{name} line {n}: {vals[big]:.3g} in column {idx[big] + 1} ({columns[big]}) is beyond "
                            f"+-{MAX_VALUE:g}, where the fits' sums of squares overflow float64", key)
        rows.append(vals)
    if len(rows) < min_rows:
        raise DataError(f"{name} has {len(rows)} data rows; at least {min_rows} are needed", key)
    data = np.asarray(rows, dtype=np.float64)
    return {c: data[:, j] for j, c in enumerate(columns)}


def number(table: dict, name: str, key: str, positive: bool = False, default=None) -> float:
    """A finite number ``table[name]`` (``default`` if absent and given); one-line errors."""
    if name not in table:
        if default is not None:
            return float(default)
        raise DataError("missing", f"{key}.{name}")
    v = table[name]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DataError(f"must be a number, got {show(v)}", f"{key}.{name}")
    if isinstance(v, int) and not -2**63 <= v < 2**63:
        raise DataError(f"must be a number a float64 holds, got {show(v)}", f"{key}.{name}")
    v = float(v)
    if not math.isfinite(v):
        raise DataError("must be finite", f"{key}.{name}")
    if positive and v <= 0:
        raise DataError(f"must be > 0, got {v:g}", f"{key}.{name}")
    return v
