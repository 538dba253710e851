"""Files written so that a failure never destroys what was there: temporary file + rename.

Every file the command line writes goes through this module. The new content is written to a
temporary file in the target's own folder (``.<name>.<random>.tmp<suffix>``), flushed to disk,
and renamed onto the target in one step (``os.replace``, atomic on POSIX). A full disk, an
unwritable folder or an exception while the content is produced leaves the previous file
byte-identical and no temporary file behind; the error is an
:class:`~cosim.core.errors.OutputError` naming the target (exit code 1).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from cosim.core.errors import OutputError

__all__ = [
    "fsync_folder",
    "open_replacing",
    "output_error",
    "replacing",
    "write_bytes",
    "write_text",
]


def _default_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


#: Permissions of written files (what ``open(path, "w")`` gives under the process umask).
FILE_MODE = _default_mode()


def output_error(path: str | Path, exc: BaseException) -> OutputError:
    """One-line :class:`OutputError` for a failed write of ``path``."""
    reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return OutputError(f"{path}: cannot write: {reason}")


def fsync_folder(folder: str | Path) -> None:
    """Flush a folder's entries (a rename) to disk; best effort."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _make_folder(folder: Path, target: Path) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{target}: cannot write: '{folder}' is not a folder") from None
    except OSError as exc:
        raise output_error(target, exc) from None


@contextlib.contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed onto ``path``.

    The temporary name keeps the suffix of ``path`` (writers that choose a format by suffix,
    such as matplotlib, see the right one). The folder is created when missing.

    Raises
    ------
    OutputError
        When creating, writing or renaming fails with an ``OSError``; ``path`` is unchanged.
    """
    path = Path(path)
    folder = path.parent
    _make_folder(folder, path)
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.",
                                    suffix=".tmp" + path.suffix)
        os.close(fd)
        os.chmod(name, FILE_MODE)
    except OSError as exc:
        raise output_error(path, exc) from None
    tmp = Path(name)
    try:
        try:
            yield tmp
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, path)
        except OSError as exc:
            raise output_error(path, exc) from None
        fsync_folder(folder)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


@contextlib.contextmanager
def open_replacing(path: str | Path, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """``open()`` on a temporary file that replaces ``path`` when the block succeeds."""
    if mode not in ("w", "wb"):
        raise ValueError(f"open_replacing: mode {mode!r} (use 'w' or 'wb')")
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
    with replacing(path) as tmp:
        try:
            with open(tmp, mode, **kwargs) as fh:
                yield fh
        except OSError as exc:
            raise output_error(path, exc) from None


def write_text(path: str | Path, text: str, encoding: str = "utf-8") -> None:
    """Replace ``path`` with ``text`` atomically."""
    with open_replacing(path, "w", encoding=encoding, newline="") as fh:
        fh.write(text)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Replace ``path`` with ``data`` atomically."""
    with open_replacing(path, "wb") as fh:
        fh.write(data)
