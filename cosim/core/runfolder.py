"""The output folder of one run, held for the run's duration.

Two runs writing into the same folder at once would interleave their files. A
:class:`RunFolder` takes an exclusive ``flock`` on the folder itself (no lock file is left
behind) for as long as the run goes; a second run into the same folder is refused at once with
a one-line :class:`~cosim.core.errors.CosimError` (exit 2) naming the folder. The lock dies with
the process, however it ends.

A folder the run created and left empty (the run was refused or failed before writing) is
removed again, so a failed command leaves no empty folder.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path
from types import TracebackType

from cosim.core import atomicio
from cosim.core.errors import CosimError

__all__ = ["RunFolder"]


class RunFolder:
    """Create (if needed) and lock ``path`` for one run; use as a context manager.

    Parameters
    ----------
    path : str or Path
        The output folder.
    option : str
        The command-line option that named it (quoted in errors).
    """

    def __init__(self, path: str | Path, option: str = "--out") -> None:
        self.path = Path(path)
        self.option = option
        self._fd: int | None = None
        self._created = False

    def __enter__(self) -> RunFolder:
        path = self.path
        if path.exists() and not path.is_dir():
            raise CosimError(f"{path}: {self.option} must be a folder, but this is a file")
        self._created = not path.exists()
        try:
            path.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
        except OSError as exc:
            raise atomicio.output_error(path, exc) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise CosimError(f"{path}: another cosim run is writing into this folder "
                             f"({self.option}); wait for it to end or choose another "
                             "folder") from None
        self._fd = fd
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        if self._created:
            with contextlib.suppress(OSError):
                self.path.rmdir()  # only when empty
