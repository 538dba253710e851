"""``cosim build-fmu`` / :func:`cosim.core.build.build_fmus`: contents, rebuild logic, errors."""

from __future__ import annotations

import shutil
import zipfile

import pytest

from cosim.cli import main
from cosim.core import build
from cosim.core.errors import CosimError


@pytest.fixture
def sandbox(tmp_path, monkeypatch):
    """A private copy of the FMU sources (the model's and the shared glue), building into
    tmp_path (the repo is untouched)."""
    src = tmp_path / "fourtank"
    shutil.copytree(build.SOURCE_DIR, src, ignore=shutil.ignore_patterns("reference"))
    shutil.copytree(build.GLUE_DIR, tmp_path / "glue")
    monkeypatch.setattr(build, "SOURCE_DIR", src)
    monkeypatch.setattr(build, "GLUE_DIR", tmp_path / "glue")
    monkeypatch.setattr(build, "FMU_DIR", tmp_path)
    monkeypatch.setattr(build, "BUILD_DIR", tmp_path / "build")
    return tmp_path


def test_fmus_contain_model_description_binary_and_sources(fmu2_path, fmu3_path):
    expected = {
        fmu2_path: {
            "modelDescription.xml",
            "binaries/linux64/FourTank.so",
            "sources/model.c",
            "sources/model.h",
            "sources/instance.h",
            "sources/instance.c",
            "sources/fmi2.c",
        },
        fmu3_path: {
            "modelDescription.xml",
            "binaries/x86_64-linux/FourTank.so",
            "sources/model.c",
            "sources/model.h",
            "sources/instance.h",
            "sources/instance.c",
            "sources/fmi3.c",
            "sources/buildDescription.xml",
        },
    }
    for path, names in expected.items():
        with zipfile.ZipFile(path) as zf:
            listed = set(zf.namelist())
            assert names <= listed
            # No FMI headers copied in: the importer provides them.
            assert not any(n.endswith("Functions.h") for n in listed)
            md = zf.read("modelDescription.xml").decode()
        version = "2.0" if path == fmu2_path else "3.0"
        assert f'fmiVersion="{version}"' in md


def test_rebuilds_only_when_sources_change(sandbox):
    paths = build.build_fmus()
    assert [p.name for p in paths] == ["FourTank.fmu", "FourTank3.fmu"]
    stamps = [p.stat().st_mtime_ns for p in paths]
    fmi2, fmi3 = build.TARGETS
    assert build.build_fmu(fmi2) is False and build.build_fmu(fmi3) is False
    assert [p.stat().st_mtime_ns for p in paths] == stamps

    glue = build.GLUE_DIR / "fmi3.c"
    glue.write_text(glue.read_text() + "\n/* changed */\n")
    assert build.build_fmu(fmi2) is False  # FMI 2 does not use fmi3.c
    assert build.build_fmu(fmi3) is True
    assert build.build_fmu(fmi3) is False
    assert build.build_fmu(fmi2, force=True) is True

    # The hash inside the FMU and the one beside it agree.
    with zipfile.ZipFile(paths[1]) as zf:
        inside = zf.read("sources/BUILD_HASH").decode().strip()
    assert inside == (build.BUILD_DIR / "FourTank3.fmu.sha256").read_text().strip()
    # A damaged FMU is rebuilt.
    paths[1].write_bytes(b"not a zip")
    assert build.build_fmu(fmi3) is True


def test_compile_error_is_one_line(sandbox):
    model = build.SOURCE_DIR / "model.c"
    model.write_text(model.read_text() + "\nthis is not C;\n")
    with pytest.raises(CosimError) as info:
        build.build_fmus()
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("compiling FourTank.fmu failed:")
    assert "model.c" in message


def test_missing_compiler(sandbox, monkeypatch, capsys):
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    with pytest.raises(CosimError, match=r"no-such-compiler-xyz.*not found"):
        build.build_fmus()
    assert main(["build-fmu"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not found" in err


def test_cli_builds_and_is_quiet(sandbox, capsys):
    assert main(["build-fmu", "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    assert (sandbox / "FourTank.fmu").is_file() and (sandbox / "FourTank3.fmu").is_file()
    assert main(["build-fmu"]) == 0
    out = capsys.readouterr().out
    assert "FourTank.fmu: up to date" in out and "FourTank3.fmu: up to date" in out
    assert main(["build-fmu", "--force"]) == 0
    assert "FourTank.fmu: built" in capsys.readouterr().out


def test_output_folder_is_the_package_folder_or_the_user_cache(tmp_path, monkeypatch):
    package = tmp_path / "fmus"
    package.mkdir()
    monkeypatch.setattr(build, "PACKAGE_DIR", package)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    assert build.output_dir() == package  # a source checkout: beside the sources
    package.chmod(0o555)  # an installed, read-only package: the user cache (even as root)
    try:
        assert build.output_dir() == tmp_path / "cache" / "gru-mpc" / "fmus"
    finally:
        package.chmod(0o755)
    assert build.writable(package) and not build.writable(tmp_path / "missing")


def test_default_plant_is_built_and_kept_up_to_date(sandbox, monkeypatch):
    from cosim.core.plants import plant_path

    fmu = plant_path(None)
    assert fmu == sandbox / "FourTank.fmu" and fmu.is_file()
    assert not (sandbox / "FourTank3.fmu").exists()  # only the plant that runs
    stamp = fmu.stat().st_mtime_ns
    assert plant_path(None) == fmu and fmu.stat().st_mtime_ns == stamp  # up to date
    model = build.SOURCE_DIR / "model.c"
    model.write_text(model.read_text() + "\n/* changed */\n")
    assert plant_path(None) == fmu and fmu.stat().st_mtime_ns != stamp  # stale: rebuilt
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    assert plant_path(None) == fmu  # no compiler: the FMU as built
    fmu.unlink()
    with pytest.raises(CosimError, match="not found"):
        plant_path(None)


def test_unwritable_output_folder_is_a_one_line_error(sandbox, monkeypatch, capsys):
    blocker = sandbox / "not-a-folder"
    blocker.write_text("")
    monkeypatch.setattr(build, "FMU_DIR", blocker / "fmus")
    monkeypatch.setattr(build, "BUILD_DIR", blocker / "fmus" / "build")
    assert main(["build-fmu"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot write" in err and "not-a-folder" in err
