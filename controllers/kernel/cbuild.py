"""Compile a C source into a shared library, cached by its content: shared by the FHOCP kernel
(:mod:`controllers.kernel.compiled_kernel`) and the simulation-error library of identification
(:mod:`controllers.identification.sim_loss`).

Libraries go to the user's cache folder (:func:`default_cache_dir`), named by a hash of the
source, the compiler's identity and the flags; every file is written under a temporary name
and renamed into place, so processes building the same library at once never compile or load
another's half-written file. Nothing here is needed for correctness: the callers fall back to
numpy or torch when no compiler is found.
"""

from __future__ import annotations

import contextlib
import functools
import os
import subprocess
import tempfile
from pathlib import Path

__all__ = ["compile_library", "compiler_id", "default_cache_dir", "write_atomic"]


def default_cache_dir() -> Path:
    """``GRU_MPC_KERNEL_CACHE``, else ``kernels`` in the user's cache folder
    (:func:`platformdirs.user_cache_dir`: ``$XDG_CACHE_HOME/gru-mpc`` or ``~/.cache/gru-mpc``
    on Linux)."""
    env = os.environ.get("GRU_MPC_KERNEL_CACHE")
    if env:
        return Path(env)
    import platformdirs

    return Path(platformdirs.user_cache_dir("gru-mpc")) / "kernels"


@functools.cache
def compiler_id(cc: str) -> str:
    """The first line of ``cc --version`` (part of every cache key)."""
    try:
        out = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30)
        return out.stdout.splitlines()[0] if out.stdout else cc
    except (OSError, subprocess.SubprocessError):
        return cc


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file renamed into place."""
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def compile_library(csource: str, cdir: Path, stem: str, cc: str, flags: tuple[str, ...],
                    libs: list[str] | tuple[str, ...] = ()) -> str | None:
    """Compile ``csource`` into ``cdir/<stem>.so`` (and keep it as ``<stem>.c``); the reason
    when it fails (the source is then kept as ``<stem>.failed.c``), else ``None``."""
    try:
        cdir.mkdir(parents=True, exist_ok=True)
        fd, csrc = tempfile.mkstemp(prefix=f"{stem}.", suffix=".c", dir=cdir)
        with os.fdopen(fd, "w") as f:
            f.write(csource)
        fd, tmp = tempfile.mkstemp(prefix=f"{stem}.", suffix=".so", dir=cdir)
        os.close(fd)
        try:
            res = subprocess.run([cc, *flags, "-o", tmp, csrc, *libs, "-lm"],
                                 capture_output=True, text=True, timeout=600)
            if res.returncode != 0:
                first = (res.stderr.strip().splitlines() or ["no message"])[0]
                kept = cdir / f"{stem}.failed.c"
                os.replace(csrc, kept)
                return f"{cc} failed on {kept}: {first[:300]}"
            os.replace(tmp, cdir / f"{stem}.so")
            os.replace(csrc, cdir / f"{stem}.c")
        finally:
            for leftover in (tmp, csrc):
                with contextlib.suppress(OSError):
                    os.unlink(leftover)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"build failed: {exc}"
    return None
