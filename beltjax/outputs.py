"""Output folders written all or nothing: one mechanism for every command.

A command writes its files into a temporary folder created next to its ``--out`` folder
(same file system); only when the whole command has succeeded are the files moved into
``--out`` (created then if missing; files of the same names replaced, other files left
alone).  On any failure the temporary folder is removed and ``--out`` is neither created
nor changed: a failing command leaves no outputs.

    with outputs.staged("out") as stage:
        folder = stage.folder()          # the temporary folder (created on first use)
        ...write files into folder...
    print("wrote " + ", ".join(map(str, stage.written)))   # the final paths

The library functions that write files (``sweep.run``, ``optimize.run``, ``identification.fit.run``)
take an output folder and report what they wrote with :func:`wrote`: it prints ``wrote ...``
when they are called directly, and stays quiet inside a stage, whose caller prints the
final paths once the move has succeeded.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import pathlib
import shutil
import tempfile

import numpy as np

from beltjax.errors import InputError

_PREFIX = ".beltjax-staging-"
_active: list["Stage"] = []  # the stages entered and not left (innermost last)


def _error(target, why: str) -> InputError:
    """The output folder cannot be created or written: one line naming --out."""
    return InputError(f"cannot create directory {str(target)!r}: {why}", "--out")


def _why(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def _existing_ancestor(path: pathlib.Path) -> pathlib.Path:
    """The nearest existing folder at or above ``path`` (as given, relative or not); an
    InputError when that is not a folder."""
    for q in (path, *path.parents):
        if q.exists() or q.is_symlink():
            if not q.is_dir():
                what = "a file" if q.is_file() else "not a directory"
                raise _error(path, f"it is {what}" if q == path else f"{str(q)!r} is {what}")
            return q
    return pathlib.Path(path.anchor or ".")


def _staging_parent(target: pathlib.Path) -> pathlib.Path:
    """Where the temporary folder goes: next to the target (in the nearest existing folder
    above it), or inside the target when it exists and that folder is on another file system
    (a mount point) or not writable."""
    here = _existing_ancestor(target)
    if here != target:  # the target does not exist yet
        return here
    up = _existing_ancestor(target.parent)
    try:
        same = up.stat().st_dev == target.stat().st_dev
    except OSError:
        same = False
    return up if up != target and same and os.access(up, os.W_OK | os.X_OK) else target


class Stage:
    """The temporary folder of one command's outputs and its move into ``target``."""

    def __init__(self, target):
        self.target = pathlib.Path(target)
        self._tmp: pathlib.Path | None = None
        self.written: list[pathlib.Path] = []  # final paths, after commit()

    def folder(self) -> pathlib.Path:
        """The temporary folder the command writes into (created on the first call, next to
        the target); an InputError when the target is a file or its parent is not writable."""
        if self._tmp is None:
            if str(self.target) == "":
                raise _error(self.target, "empty folder name")
            try:  # (a name too long for the file system fails already in looking for the target)
                parent = _staging_parent(self.target)
                self._tmp = pathlib.Path(tempfile.mkdtemp(prefix=_PREFIX, dir=parent))
            except OSError as exc:
                raise _error(self.target, _why(exc)) from None
        return self._tmp

    def commit(self) -> list[pathlib.Path]:
        """Move every file of the temporary folder into the target (created now if missing;
        files of the same names replaced).  On a failure the target is put back as it was."""
        if self._tmp is None:
            return []
        files = sorted((p for p in self._tmp.rglob("*") if p.is_file() or p.is_symlink()),
                       key=lambda p: (p.lstat().st_mtime_ns, str(p)))
        target = self.target
        created = [q for q in (target, *target.parents) if not (q.exists() or q.is_symlink())]
        backup = self._tmp.with_name(self._tmp.name + ".old")
        moved: list[tuple[pathlib.Path, pathlib.Path, pathlib.Path | None]] = []  # (new, final, backup)
        try:
            if target.exists() and not target.is_dir():
                raise _error(target, "it is a file")
            target.mkdir(parents=True, exist_ok=True)
            for src in files:
                rel = src.relative_to(self._tmp)
                dst = target / rel
                old = None
                dst.parent.mkdir(parents=True, exist_ok=True)
                if dst.is_dir() and not dst.is_symlink():
                    raise _error(target, f"{str(dst)!r} is a folder, where the file {rel} goes")
                if dst.exists() or dst.is_symlink():
                    old = backup / rel
                    old.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(dst, old)
                moved.append((src, dst, old))
                os.replace(src, dst)
        except BaseException as exc:
            for src, dst, old in reversed(moved):  # put the target back as it was
                with contextlib.suppress(OSError):
                    if dst.exists() or dst.is_symlink():
                        os.replace(dst, src)
                    if old is not None:
                        os.replace(old, dst)
            for q in created:  # folders this commit created (deepest first), if empty
                with contextlib.suppress(OSError):
                    q.rmdir()
            shutil.rmtree(backup, ignore_errors=True)
            if isinstance(exc, OSError):
                raise _error(target, _why(exc)) from None
            raise
        shutil.rmtree(backup, ignore_errors=True)
        self.written = [target / p.relative_to(self._tmp) for p in files]
        return self.written

    def discard(self) -> None:
        """Remove the temporary folder and everything in it."""
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            shutil.rmtree(self._tmp.with_name(self._tmp.name + ".old"), ignore_errors=True)
            self._tmp = None


@contextlib.contextmanager
def staged(target):
    """A :class:`Stage` for ``target``: its files are moved into ``target`` when the block ends
    normally, and thrown away (``target`` untouched) when it raises."""
    stage = Stage(target)
    _active.append(stage)
    try:
        yield stage
        stage.commit()
    finally:
        _active.remove(stage)
        stage.discard()


def active() -> Stage | None:
    """The innermost stage entered and not left, or None."""
    return _active[-1] if _active else None


def written_line(paths) -> str:
    """``wrote a, b and c``: the line that lists files written."""
    names = [str(p) for p in paths]
    if not names:
        return "wrote nothing"
    return "wrote " + (names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1])


def wrote(paths) -> None:
    """Report files written by a library function: print them, unless a stage is active
    (its caller prints the final paths after the move)."""
    if active() is None:
        print(written_line(paths))


def jsonable(x):
    """``x`` with numpy scalars and arrays as Python numbers and lists, and every non-finite float
    as None (JSON has no NaN or infinity: a strict reader would reject the file)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    return x


def write_json(path: pathlib.Path, data) -> None:
    """The one results writer: ``data`` as strict JSON (:func:`jsonable`), indented, at ``path``."""
    pathlib.Path(path).write_text(json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")
