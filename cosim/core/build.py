"""Build the four-tank plant FMUs from their C sources.

``build_fmus()`` compiles the sources of the :mod:`fmus` package, the model
``fmus/fourtank/model.c`` with the FMI glue every C model shares (``fmus/glue/instance.c``
and ``fmi2.c`` or ``fmi3.c``, as the Modelica Reference-FMUs share theirs), with gcc against
the FMI headers shipped with fmpy (``fmpy/c-code``) and zips two source-and-binary FMUs:

* ``FourTank.fmu`` -- FMI 2.0, Co-Simulation and Model Exchange, binary under
  ``binaries/linux64/``;
* ``FourTank3.fmu`` -- FMI 3.0, Co-Simulation and Model Exchange, binary under
  ``binaries/x86_64-linux/``, with ``sources/buildDescription.xml``.

The sources are package data, found through the installed ``fmus`` package (never through
a repository's layout). The FMUs go to :data:`FMU_DIR`: the ``fmus`` package folder itself
when it is writable (in a source checkout: ``fmus/FourTank.fmu``), else the user cache
folder ``platformdirs.user_cache_dir("gru-mpc")/fmus`` (``~/.cache/gru-mpc/fmus`` on Linux,
``$XDG_CACHE_HOME`` respected). Intermediate files go to ``build/`` there. An FMU is rebuilt
only when its inputs change: the SHA-256 of the sources, the model description, the compiler
command and the compiler version is stored in ``build/<name>.sha256`` and inside the FMU as
``sources/BUILD_HASH``.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import stat
import subprocess
import zipfile
from dataclasses import dataclass
from pathlib import Path

import fmus
from cosim.core.errors import CosimError

__all__ = [
    "BUILD_DIR",
    "CACHE_APP",
    "CFLAGS",
    "DEFAULT_PROBLEM",
    "FMU_DIR",
    "GLUE_DIR",
    "GLUE_FILES",
    "LDFLAGS",
    "MODEL_IDENTIFIER",
    "PACKAGE_DIR",
    "SOURCE_DIR",
    "TARGETS",
    "Target",
    "add_member",
    "build_fmu",
    "build_fmus",
    "cache_dir",
    "check_platform",
    "compiler",
    "default_plant",
    "display_path",
    "fmi_headers_dir",
    "output_dir",
    "run_compiler",
    "source_path",
    "writable",
]

#: The ``fmus`` package folder: ``fmus/`` of a source checkout, or of site-packages.
PACKAGE_DIR = Path(fmus.__file__).resolve().parent
#: The four-tank plant's C sources and model descriptions (package data).
SOURCE_DIR = PACKAGE_DIR / "fourtank"
#: The FMI glue every C plant model shares (package data).
GLUE_DIR = PACKAGE_DIR / "glue"
#: The shared glue's files (found in :data:`GLUE_DIR`; every other source in the model's
#: folder).
GLUE_FILES = ("instance.h", "instance.c", "fmi2.c", "fmi3.c")
#: The four-tank's control problem (signals, boxes, Ts, PI loops): the default problem of the
#: default plant (:mod:`cosim.adapters.problems`).
DEFAULT_PROBLEM = SOURCE_DIR / "problem.toml"
#: The application's name in the user cache folder (the compiled kernels share it).
CACHE_APP = "gru-mpc"
MODEL_IDENTIFIER = "FourTank"


def writable(folder: Path) -> bool:
    """Whether ``folder`` may be written into: it exists, we have write access, and its
    permission bits allow writing (a folder made read-only with ``chmod a-w`` counts as
    read-only even for root)."""
    try:
        mode = folder.stat().st_mode
    except OSError:
        return False
    return (stat.S_ISDIR(mode) and bool(mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
            and os.access(folder, os.W_OK | os.X_OK))


def cache_dir() -> Path:
    """The user cache folder of the FMUs: ``platformdirs.user_cache_dir("gru-mpc")/fmus``."""
    import platformdirs

    return Path(platformdirs.user_cache_dir(CACHE_APP)) / "fmus"


def output_dir() -> Path:
    """Where the FMUs are built: beside their sources when that folder is writable (a source
    checkout), else :func:`cache_dir` (an installed, read-only package)."""
    return PACKAGE_DIR if writable(PACKAGE_DIR) else cache_dir()


#: The folder of the built FMUs (:func:`output_dir`, chosen when this module is imported).
FMU_DIR = output_dir()
#: Intermediate files (compiled libraries, hash stamps).
BUILD_DIR = FMU_DIR / "build"

#: Compiler flags: strict C99, warnings are errors, only the FMI functions are exported.
CFLAGS = (
    "-std=c99",
    "-Wall",
    "-Wextra",
    "-Werror",
    "-pedantic",
    "-O2",
    "-fPIC",
    "-shared",
    "-fvisibility=hidden",
)
LDFLAGS = ("-Wl,--no-undefined", "-lm")


@dataclass(frozen=True)
class Target:
    """One FMU to build: its FMI version, file name, glue source and binary folder.

    Both FMUs share ``model.c`` (equations) and ``instance.c`` (the FMI-version-independent
    layer); ``glue`` is the thin FMI 2.0 or 3.0 adapter. Inside the FMU every source lies
    flat under ``sources/``.
    """

    fmi_version: int
    fmu_name: str
    glue: str
    model_description: str
    platform_dir: str

    @property
    def fmu_path(self) -> Path:
        return FMU_DIR / self.fmu_name

    @property
    def sources(self) -> tuple[str, ...]:
        """Files shipped under ``sources/`` (FMI 3 adds its buildDescription.xml)."""
        extra = ("buildDescription.xml",) if self.fmi_version == 3 else ()
        return ("model.h", "model.c", "instance.h", "instance.c", self.glue, *extra)


def source_path(name: str) -> Path:
    """Where source ``name`` of a :class:`Target` lies: the shared glue's folder or the
    model's."""
    return (GLUE_DIR if name in GLUE_FILES else SOURCE_DIR) / name


TARGETS = (
    Target(2, "FourTank.fmu", "fmi2.c", "modelDescription2.xml", "linux64"),
    Target(3, "FourTank3.fmu", "fmi3.c", "modelDescription3.xml", "x86_64-linux"),
)


def fmi_headers_dir() -> Path:
    """Return fmpy's folder of FMI 1/2/3 C headers (``fmpy/c-code``)."""
    import fmpy

    path = Path(fmpy.__file__).parent / "c-code"
    if not (path / "fmi2Functions.h").is_file() or not (path / "fmi3Functions.h").is_file():
        raise CosimError(f"FMI headers not found in {path}: reinstall fmpy")
    return path


def compiler() -> str:
    """Return the C compiler to use (``$CC`` or ``gcc``), or raise :class:`CosimError`."""
    cc = os.environ.get("CC", "gcc")
    found = shutil.which(cc)
    if found is None:
        raise CosimError(
            f"C compiler '{cc}' not found: install gcc (e.g. apt-get install gcc) to build the FMUs"
        )
    return found


def display_path(path: Path) -> str:
    """``path`` relative to the current folder when inside it, else absolute (messages)."""
    try:
        return str(path.relative_to(Path.cwd()))
    except (ValueError, OSError):
        return str(path)


def compiler_version(cc: str) -> str:
    """The first line of ``cc --version`` (part of every build's key)."""
    try:
        out = subprocess.run([cc, "--version"], capture_output=True, text=True, check=False)
    except OSError as exc:
        raise CosimError(f"cannot run C compiler {cc}: {exc}") from exc
    return out.stdout.splitlines()[0] if out.stdout else ""


def _source_hash(target: Target, cc: str) -> str:
    digest = hashlib.sha256()
    for name in (*target.sources, target.model_description):
        path = source_path(name)
        if not path.is_file():
            raise CosimError(f"missing FMU source {display_path(path)}")
        digest.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update(" ".join((*CFLAGS, *LDFLAGS)).encode())
    digest.update(compiler_version(cc).encode())
    digest.update(Path(__file__).read_bytes())
    return digest.hexdigest()


def check_platform() -> None:
    """Raise :class:`CosimError` unless this is x86-64 Linux (the FMUs' only platform)."""
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise CosimError(
            f"building the FMUs is supported on x86_64 Linux only, not "
            f"{platform.system()} {platform.machine()}"
        )


def _compile(target: Target, cc: str, out: Path) -> None:
    include = fmi_headers_dir()
    sources = [str(source_path(name)) for name in target.sources if name.endswith(".c")]
    cmd = [cc, *CFLAGS, f"-I{include}", f"-I{SOURCE_DIR}", f"-I{GLUE_DIR}", "-o", str(out),
           *sources, *LDFLAGS]
    run_compiler(cmd, target.fmu_name)


def run_compiler(cmd: list[str], what: str) -> None:
    """Run the compiler command ``cmd`` (its first element the compiler) building ``what``;
    a failure raises :class:`CosimError` in one line: its first error line."""
    try:
        result = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=600)
    except (OSError, subprocess.SubprocessError) as exc:
        raise CosimError(f"cannot run C compiler {cmd[0]}: {exc}") from None
    if result.returncode != 0:
        lines = [ln for ln in result.stderr.splitlines() if "error" in ln] or [
            ln for ln in result.stderr.splitlines() if ln.strip()
        ]
        first = lines[0].strip() if lines else f"exit status {result.returncode}"
        raise CosimError(f"compiling {what} failed: {first}")


#: Time stamp of every FMU member: the same sources give the same FMU, byte for byte (a
#: campaign's fingerprint, ``--resume``, survives a rebuild).
ZIP_DATE = (2000, 1, 1, 0, 0, 0)


def add_member(zf: zipfile.ZipFile, arcname: str, data: bytes, executable: bool = False
               ) -> None:
    """One member with a fixed time stamp and permissions (a reproducible archive)."""
    info = zipfile.ZipInfo(arcname, date_time=ZIP_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = (0o755 if executable else 0o644) << 16
    zf.writestr(info, data)


def _zip_fmu(target: Target, binary: Path, digest: str) -> None:
    """Write the FMU atomically (temporary file, then rename): a failure keeps the old one."""
    from cosim.core.atomicio import replacing

    with replacing(target.fmu_path) as tmp, \
            zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        members = [(SOURCE_DIR / target.model_description, "modelDescription.xml"),
                   (binary, f"binaries/{target.platform_dir}/{MODEL_IDENTIFIER}.so")]
        members += [(source_path(name), f"sources/{name}") for name in target.sources]
        for path, arcname in members:
            add_member(zf, arcname, path.read_bytes(), executable=arcname.endswith(".so"))
        add_member(zf, "sources/BUILD_HASH", (digest + "\n").encode())


def _stored_hash(target: Target) -> str | None:
    stamp = BUILD_DIR / f"{target.fmu_name}.sha256"
    if not target.fmu_path.is_file() or not stamp.is_file():
        return None
    try:
        with zipfile.ZipFile(target.fmu_path) as zf:
            inside = zf.read("sources/BUILD_HASH").decode().strip()
    except (KeyError, zipfile.BadZipFile, OSError):
        return None
    beside = stamp.read_text().strip()
    return inside if inside == beside else None


def build_fmu(target: Target, force: bool = False) -> bool:
    """Build one FMU if its inputs changed (or ``force``); return True when it was rebuilt.

    Raises
    ------
    CosimError
        gcc is missing, the platform is not x86_64 Linux, or compilation failed.
    OutputError
        :data:`FMU_DIR` cannot be written (the previous FMU, if any, is intact).
    """
    from cosim.core.atomicio import output_error, write_text

    cc = compiler()
    digest = _source_hash(target, cc)
    if not force and _stored_hash(target) == digest:
        return False
    check_platform()
    out_dir = BUILD_DIR / f"fmi{target.fmi_version}"
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_error(out_dir, exc) from None
    # Compile to a private name first: concurrent builds (parallel test runs) never zip a
    # half-written library.
    binary = out_dir / f"{MODEL_IDENTIFIER}.{os.getpid()}.so"
    try:
        _compile(target, cc, binary)
        binary = binary.replace(out_dir / f"{MODEL_IDENTIFIER}.so")
        _zip_fmu(target, binary, digest)
    finally:
        (out_dir / f"{MODEL_IDENTIFIER}.{os.getpid()}.so").unlink(missing_ok=True)
    write_text(BUILD_DIR / f"{target.fmu_name}.sha256", digest + "\n")
    return True


def build_fmus(force: bool = False) -> list[Path]:
    """Build ``FourTank.fmu`` (FMI 2.0) and ``FourTank3.fmu`` (FMI 3.0) in :data:`FMU_DIR`.

    Parameters
    ----------
    force
        Rebuild even when the sources are unchanged.

    Returns
    -------
    list of Path
        The two FMU paths (FMI 2.0 first), whether rebuilt or already up to date.

    Raises
    ------
    CosimError, OutputError
        As :func:`build_fmu`, for the first FMU that fails (the previous FMUs, if any, are
        intact).
    """
    for target in TARGETS:
        build_fmu(target, force=force)
    return [target.fmu_path for target in TARGETS]


def default_plant() -> Path:
    """The project's plant FMU (FMI 2.0), built when missing and rebuilt when stale.

    With a C compiler at hand, ``FourTank.fmu`` is brought up to date with its sources
    (a no-op when it is: only the hash is computed), so that a cached FMU never outlives an
    upgrade of the package; without one, an FMU already built is used as it is.

    Raises
    ------
    CosimError
        The FMU is missing and cannot be built here (no gcc, another platform, a compile
        error).
    OutputError
        :data:`FMU_DIR` cannot be written.
    """
    target = TARGETS[0]
    if target.fmu_path.is_file():
        try:
            compiler()
        except CosimError:
            return target.fmu_path
    build_fmu(target)
    return target.fmu_path
