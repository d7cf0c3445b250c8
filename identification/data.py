"""Reading identification datasets: the one-line error and the CSV reader every fit uses."""

from __future__ import annotations

import math
import pathlib
from typing import Sequence

import numpy as np

from beltjax.errors import BeltjaxError


class DataError(BeltjaxError):
    """Bad identification data: one line naming the key, file or cause."""

    def __init__(self, key: str, message: str):
        super().__init__(message, key)


def read_csv(path: pathlib.Path, columns: Sequence[str], key: str, min_rows: int = 3) -> dict[str, np.ndarray]:
    """Columns of a CSV file with a header line: {name: float64 array}.

    ``columns`` must all be present (extra columns are ignored); every value must be a finite
    number; at least ``min_rows`` rows.  Raises :class:`DataError` naming ``key`` and the file.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise DataError(key, f"file {str(path)!r} not found")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(key, f"cannot read {path.name}: {e}") from None
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1)
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise DataError(key, f"{path.name} is empty")
    header = [h.strip() for h in lines[0][1].split(",")]
    missing = [c for c in columns if c not in header]
    if missing:
        raise DataError(key, f"{path.name} lacks column(s) {', '.join(missing)} (has {', '.join(header)})")
    idx = [header.index(c) for c in columns]
    rows = []
    for n, ln in lines[1:]:
        cells = [c.strip() for c in ln.split(",")]
        if len(cells) != len(header):
            raise DataError(key, f"{path.name} line {n}: {len(cells)} values for {len(header)} columns")
        try:
            vals = [float(cells[i]) for i in idx]
        except ValueError:
            raise DataError(key, f"{path.name} line {n}: not a number in {ln.strip()!r}") from None
        if not all(math.isfinite(v) for v in vals):
            raise DataError(key, f"{path.name} line {n}: NaN or infinite value")
        rows.append(vals)
    if len(rows) < min_rows:
        raise DataError(key, f"{path.name} has {len(rows)} data rows; at least {min_rows} are needed")
    data = np.asarray(rows, dtype=np.float64)
    return {c: data[:, j] for j, c in enumerate(columns)}


def number(table: dict, name: str, key: str, positive: bool = False, default=None) -> float:
    """A finite number ``table[name]`` (``default`` if absent and given); one-line errors."""
    if name not in table:
        if default is not None:
            return float(default)
        raise DataError(f"{key}.{name}", "missing")
    v = table[name]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DataError(f"{key}.{name}", f"must be a number, got {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise DataError(f"{key}.{name}", "must be finite")
    if positive and v <= 0:
        raise DataError(f"{key}.{name}", f"must be > 0, got {v:g}")
    return v
