"""How the ``cosim`` command leaves the process (:func:`cosim.cli.entry`): a command that
loaded an FMU runs Python's exit handlers, then exits without running the native destructors
of the libraries still loaded (an FMU's may crash: pythonfmu's reads freed memory at exit),
so that its exit code is its own."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

#: A library whose destructor aborts the process, as a crashing FMU destructor would.
ABORTING = '#include <stdlib.h>\n__attribute__((destructor)) static void bye(void) { abort(); }\n'

SCRIPT = """
import atexit, ctypes, sys
from pathlib import Path
ctypes.CDLL(sys.argv[1])                                 # loaded, never unloaded
atexit.register(Path(sys.argv[2]).write_text, "ran")     # a Python exit handler
sys.argv = ["cosim", "run", sys.argv[3], "--plant", sys.argv[4], "--controller", "pi",
            "--out", sys.argv[5], "--quiet", "--no-figure"]
from cosim.cli import entry
entry()
"""


@pytest.mark.skipif(shutil.which("gcc") is None, reason="no C compiler")
@pytest.mark.parametrize("plant", ["fmu", "none"])
def test_a_command_that_loaded_an_fmu_skips_native_destructors(
        plant: str, fmu2_path: Path, tmp_path: Path) -> None:
    lib = tmp_path / "aborting.so"
    (tmp_path / "aborting.c").write_text(ABORTING)
    subprocess.run(["gcc", "-shared", "-fPIC", "-o", str(lib), str(tmp_path / "aborting.c")],
                   check=True)
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n100,,\n")
    marker = tmp_path / "atexit.txt"
    # without an FMU (a scenario that fails before loading one), the process exits as usual:
    # the aborting destructor runs
    fmu = str(fmu2_path) if plant == "fmu" else str(tmp_path / "missing.fmu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(lib), str(marker), str(scenario),
                           fmu, str(tmp_path / "out")], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert marker.read_text() == "ran", proc.stderr
    if plant == "fmu":
        assert proc.returncode == 0, proc.stderr
        assert (tmp_path / "out" / "summary.json").is_file()
    else:
        assert proc.returncode == -6 and "plant FMU not found" in proc.stderr
