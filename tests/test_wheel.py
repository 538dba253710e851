"""The wheel works anywhere: built, installed in a fresh venv, run with nothing of the repo.

``pip wheel .`` must carry everything an installed package needs at run time as package
data: the compiled kernel's C template (``controllers/kernel/*.c``; without it the robust MPC
silently falls back to the numpy derivatives), the plant FMU's C sources and model
descriptions (``fmus/fourtank/``) and the shipped model (``controllers/models/``). The wheel
is then installed in a fresh virtual environment (its dependencies from PyPI or pip's cache,
not the ``train`` extra) and ``cosim run`` and ``cosim campaign`` run from an empty folder in
a clean environment: no ``PYTHONPATH``, ``HOME`` and ``XDG_CACHE_HOME`` in a temporary folder
(every cache starts empty), the installed package folders read-only, so that the plant FMU
and the compiled kernel are built into the user cache (``$XDG_CACHE_HOME/gru-mpc``).
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
#: What ``pip wheel`` reads: the project's metadata and its packages.
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "cosim", "controllers",
           "fmus")
#: Build outputs and caches that a checkout may hold and a wheel must not carry.
NOT_SOURCES = shutil.ignore_patterns("__pycache__", "*.pyc", "build", "*.egg-info", "*.fmu",
                                     ".*")
#: The installed packages (made read-only while the commands run).
PACKAGES = ("cosim", "controllers", "fmus")
#: A short scenario (13 steps of 25 s): the written form of scenarios/*.csv.
SCENARIO = "time,ref.h1,ref.h2\n0,0.65,0.65\n125,0.8,\n325,,\n"


def _tail(proc: subprocess.CompletedProcess) -> str:
    return (proc.stdout + proc.stderr)[-3000:]


def _run(cmd: list[str], timeout: float = 600, **kwargs: object) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False,
                          **kwargs)  # type: ignore[call-overload]


def _package_data() -> set[str]:
    """Files the installed package reads at run time, as paths inside the wheel."""
    from controllers.kernel.compiled_kernel import LOADER_C, TEMPLATE_PARTS
    from controllers.kernel.controller_source import CONTROLLER_C
    from controllers.model import DEFAULT_MODEL
    from cosim.core.build import DEFAULT_PROBLEM, PACKAGE_DIR, TARGETS, source_path

    names = {f"controllers/kernel/{p.name}" for p in (*TEMPLATE_PARTS, CONTROLLER_C, LOADER_C)}
    names |= {"fmus/controller/model.c", "fmus/controller/model.h"}
    names |= {f"fmus/{source_path(name).relative_to(PACKAGE_DIR).as_posix()}" for t in TARGETS
              for name in (*t.sources, t.model_description)}
    return names | {f"controllers/models/{DEFAULT_MODEL.name}", "fmus/__init__.py",
                    f"fmus/fourtank/{DEFAULT_PROBLEM.name}"}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel of a copy of this checkout's sources (no build outputs in reach)."""
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=NOT_SOURCES)
        else:
            src.mkdir(exist_ok=True)
            shutil.copy2(path, src / name)
    proc = _run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q",
                 "-w", str(base / "dist")])
    assert proc.returncode == 0, _tail(proc)
    (found,) = (base / "dist").glob("gru_mpc_cosim-*.whl")
    return found


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment with the wheel installed (dependencies from PyPI)."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc not found: the installed package builds its FMU and kernel with it")
    env_dir = tmp_path_factory.mktemp("venv") / "venv"
    proc = _run([sys.executable, "-m", "venv", str(env_dir)])
    assert proc.returncode == 0, _tail(proc)
    proc = _run([str(env_dir / "bin" / "python"), "-m", "pip", "install", "-q", str(wheel)])
    assert proc.returncode == 0, _tail(proc)
    return env_dir


@pytest.fixture(scope="module")
def site_packages(venv: Path) -> Iterator[Path]:
    """The venv's site-packages, its installed package folders read-only until teardown."""
    (site,) = (venv / "lib").glob("python3*/site-packages")
    folders = [p for name in PACKAGES for p in [site / name, *(site / name).rglob("*")]
               if p.is_dir() and p.name != "__pycache__"]
    modes = {p: p.stat().st_mode for p in folders}
    try:
        for path, mode in modes.items():
            path.chmod(stat.S_IMODE(mode) & ~0o222)
        yield site
    finally:
        for path, mode in modes.items():
            path.chmod(stat.S_IMODE(mode))


def _clean_env(venv: Path, home: Path) -> dict[str, str]:
    """Nothing inherited: the venv's bin first on PATH, gcc reachable, fresh HOME and cache."""
    gcc = Path(shutil.which("gcc") or "/usr/bin/gcc").parent
    path = os.pathsep.join([str(venv / "bin"), str(gcc), os.defpath])
    return {"PATH": path, "HOME": str(home / "home"), "XDG_CACHE_HOME": str(home / "cache"),
            "LANG": "C.UTF-8"}


def _empty_folder(tmp_path: Path) -> Path:
    work = tmp_path / "work"
    work.mkdir()
    assert not work.resolve().is_relative_to(ROOT)
    return work


def test_the_wheel_carries_the_package_data(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = sorted(_package_data() - names)
    assert not missing, f"{wheel.name} lacks {missing}"
    modules = {p.relative_to(ROOT).as_posix() for package in ("cosim", "controllers")
               for p in (ROOT / package).rglob("*.py") if "__pycache__" not in p.parts}
    assert not sorted(modules - names), sorted(modules - names)
    stray = sorted(n for n in names if n.startswith(("fmus/thirdparty/", "fmus/build/",
                                                     "fmus/fourtank/reference/", "tests/"))
                   or n.endswith((".fmu", ".so", ".pyc")))
    assert not stray, f"{wheel.name} carries {stray}"


def test_cosim_run_from_an_empty_folder(venv: Path, site_packages: Path,
                                        tmp_path: Path) -> None:
    env = _clean_env(venv, tmp_path)
    work = _empty_folder(tmp_path)
    (work / "steps.csv").write_text(SCENARIO)

    proc = _run([str(venv / "bin" / "cosim"), "run", "steps.csv", "--out", "out"], cwd=work,
                env=env)
    assert proc.returncode == 0, _tail(proc)
    assert "Traceback" not in proc.stderr
    summary_text = (work / "out" / "summary.json").read_text()
    summary = json.loads(summary_text)
    assert summary["status"] == "ok" and summary["steps"] == 13
    ctrl = summary["controller_summary"]
    assert ctrl["kernel"] == "compiled", "the installed robust MPC fell back to numpy"

    cache = tmp_path / "cache" / "gru-mpc"
    assert summary["plant"] == str(cache / "fmus" / "FourTank.fmu")
    assert (cache / "fmus" / "FourTank.fmu").is_file()
    assert list((cache / "kernels").glob("*.so")), "no compiled kernel in the user cache"
    assert Path(ctrl["model"]).is_relative_to(site_packages)
    assert not (site_packages / "fmus" / "FourTank.fmu").exists()
    assert not (site_packages / "fmus" / "build").exists()
    assert str(ROOT) not in summary_text

    # `cosim build-fmu` writes into the same cache folder and says so
    proc = _run([str(venv / "bin" / "cosim"), "build-fmu"], cwd=work, env=env)
    assert proc.returncode == 0, _tail(proc)
    assert f"{cache / 'fmus' / 'FourTank.fmu'}: up to date" in proc.stdout, proc.stdout
    assert f"{cache / 'fmus' / 'FourTank3.fmu'}: built" in proc.stdout, proc.stdout

    # the controller FMU builds from the installed sources, and runs in place of the MPC
    proc = _run([str(venv / "bin" / "cosim"), "export-fmu", "--out", "Mpc.fmu", "--quiet"],
                cwd=work, env=env)
    assert proc.returncode == 0, _tail(proc)
    proc = _run([str(venv / "bin" / "cosim"), "run", "steps.csv", "--controller", "Mpc.fmu",
                 "--out", "fmu"], cwd=work, env=env)
    assert proc.returncode == 0, _tail(proc)
    fmu_rows = (work / "fmu" / "results.csv").read_text().splitlines()
    py_rows = (work / "out" / "results.csv").read_text().splitlines()
    qa = [[row.split(",")[rows[0].split(",").index('"ctrl.qa"')] for row in rows[1:]]
          for rows in (fmu_rows, py_rows)]
    assert qa[0] == qa[1]

    # and the packages that ran are the installed ones, nothing of the repository in reach
    probe = ("import json, sys, cosim, controllers, fmus; print(json.dumps("
             "[m.__file__ for m in (cosim, controllers, fmus)] + sys.path))")
    proc = _run([str(venv / "bin" / "python"), "-c", probe], cwd=work, env=env)
    assert proc.returncode == 0, _tail(proc)
    found = json.loads(proc.stdout)
    files, path = found[:3], found[3:]
    assert all(Path(f).is_relative_to(site_packages) for f in files), files
    assert not [p for p in path if p and Path(p).resolve().is_relative_to(ROOT)], path


@pytest.mark.parametrize("spec", ["theorem", "plant_uncertainty"])
def test_cosim_campaign_on_a_shipped_spec(spec: str, venv: Path, site_packages: Path,
                                          tmp_path: Path) -> None:
    # the spec names ../paper_steps.csv and model:../../controllers/models/...: same layout
    tree = tmp_path / "specs"
    (tree / "scenarios" / "campaigns").mkdir(parents=True)
    (tree / "controllers" / "models").mkdir(parents=True)
    shutil.copy2(ROOT / "scenarios" / "paper_steps.csv", tree / "scenarios")
    shutil.copy2(ROOT / "controllers" / "models" / "fourtank_gru.json",
                 tree / "controllers" / "models")
    text = (ROOT / "scenarios" / "campaigns" / f"{spec}.toml").read_text(encoding="utf-8")
    assert "\nruns = 200\n" in text
    spec_file = tree / "scenarios" / "campaigns" / f"{spec}.toml"
    spec_file.write_text(text.replace("\nruns = 200\n", "\nruns = 2\n"), encoding="utf-8")
    env = _clean_env(venv, tmp_path)
    work = _empty_folder(tmp_path)

    proc = _run([str(venv / "bin" / "cosim"), "campaign", str(spec_file), "--workers", "1",
                 "--out", "out"], cwd=work, env=env)
    assert proc.returncode == 0, _tail(proc)
    assert "Traceback" not in proc.stderr
    summary = json.loads((work / "out" / "summary.json").read_text())
    planned = 2 * len(summary["variants"])
    assert summary["planned"] == summary["runs"] == summary["ok"] == planned, summary
    assert summary["failed"] == 0
    assert not (site_packages / "fmus" / "FourTank.fmu").exists()
    if spec == "plant_uncertainty":  # the FMU plant: built into the user cache
        assert (tmp_path / "cache" / "gru-mpc" / "fmus" / "FourTank.fmu").is_file()
