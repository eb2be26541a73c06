"""Output paths checked before anything runs: can this folder be made and written, this file written?

Every command that writes (``run --out/--video``, ``campaign --out``, ``fidelity --out``,
``plan --plot``, ``show --png``) calls :func:`check_folder` or :func:`check_file` on its
paths first, so a path it cannot write is bad input (exit 2, the option and the path
named) before a plan, a run or a campaign starts, not a traceback after it.

Writability is tested by doing, not by permission bits (which ``root`` ignores): a
probe file is created in the deepest folder that exists and removed at once. Nothing
is left behind and no missing folder is created.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

from executive.errors import ExecutiveError

__all__ = ["OutputPathError", "check_file", "check_folder"]


class OutputPathError(ExecutiveError):
    """An output path that cannot be written: the option, the path and why."""

    def __init__(self, option: str, path: str | Path, problem: str) -> None:
        self.option, self.path, self.problem = option, str(path), problem
        super().__init__(f"{option} {path!s}: cannot write there: {problem}")


def _reason(exc: OSError) -> str:
    """An OSError's cause in words, without the repeated path."""
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return f"not writable ({exc.strerror})"
    return exc.strerror or str(exc)


def _existing_ancestor(option: str, path: Path, start: Path) -> Path:
    """The deepest existing folder of ``start`` (itself included); errors name ``path``."""
    current = start
    while True:
        try:
            if current.exists():
                break
            if os.path.lexists(current):  # a link to nothing, or a loop of links
                raise OutputPathError(
                    option, path, f"{current} is a broken symbolic link (or a loop of them)"
                )
        except OSError as exc:  # a symlink loop, a name too long, ...
            raise OutputPathError(option, path, f"{current}: {_reason(exc)}") from None
        if current.parent == current:
            break
        current = current.parent
    if not current.is_dir():
        what = "it is" if current == path else f"it is inside {current}, which is"
        raise OutputPathError(option, path, f"{what} a file, not a folder")
    return current


def _probe(option: str, path: Path, folder: Path) -> None:
    """Create and remove a file in ``folder``; an OutputPathError naming ``path`` if that fails."""
    try:
        fd, name = tempfile.mkstemp(prefix=".executive-probe-", dir=folder)
    except OSError as exc:
        raise OutputPathError(option, path, f"the folder {folder} is {_reason(exc)}") from None
    os.close(fd)
    os.unlink(name)


def _as_path(option: str, path: str | Path) -> Path:
    text = os.fspath(path)
    if not text:
        raise OutputPathError(option, "''", "the path is empty")
    if "\0" in text:
        raise OutputPathError(option, repr(text), "the path contains a NUL byte")
    return Path(text)  # as the writer will open it: a quoted "~" is a folder named "~"


def check_folder(path: str | Path, option: str) -> Path:
    """``path`` as a Path if it is (or can be created as) a folder this process can write.

    ``option`` names where the path came from (``--out``) for the message. Raises
    :class:`OutputPathError` when ``path`` or one of its parents is a file, or when the
    folder (or the deepest existing parent it would be created in) is not writable.
    """
    folder = _as_path(option, path)
    existing = _existing_ancestor(option, folder, folder)
    _probe(option, folder, existing)
    return folder


def check_file(path: str | Path, option: str) -> Path:
    """``path`` as a Path if this process can write that file (creating its folder if needed).

    Raises :class:`OutputPathError` when ``path`` is a folder, when a parent is a file, or
    when the file or its folder is not writable. An existing file is opened for appending
    and closed unchanged.
    """
    file = _as_path(option, path)
    try:
        is_dir = file.is_dir()
    except OSError as exc:
        raise OutputPathError(option, file, _reason(exc)) from None
    if is_dir:
        raise OutputPathError(option, file, "it is a folder; give a file name")
    existing = _existing_ancestor(option, file, file.parent)
    if existing == file.parent and file.exists():
        try:
            with open(file, "ab"):
                pass
        except OSError as exc:
            raise OutputPathError(option, file, f"the file is {_reason(exc)}") from None
    else:
        _probe(option, file, existing)
    return file
