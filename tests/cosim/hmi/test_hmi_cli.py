"""Bad input to the page's options is one line naming the flag or file, exit 2, no traceback
and nothing run or written; the users file holds hashes, never a password."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.hmi.users import Users
from tests.cosim.hmi.browser import env

SHORT = "time,ref.h1,ref.h2\n0,0.65,0.65\n100,,\n"


def one_line(capsys: pytest.CaptureFixture, argv: list[str]) -> str:
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "Traceback" not in err[0], (code, err)
    return err[0]


@pytest.fixture
def scenario(tmp_path: Path) -> Path:
    path = tmp_path / "short.csv"
    path.write_text(SHORT)
    return path


@pytest.mark.parametrize(("flag", "expected"), [
    ("nope", "--hmi nope: expected [HOST:]PORT"),
    ("127.0.0.1:70000", "--hmi 127.0.0.1:70000: expected [HOST:]PORT"),
    (":8050", "--hmi :8050: expected [HOST:]PORT"),
    ("192.0.2.1:8050", "--hmi 192.0.2.1:8050: a page on an address other than the loopback "
                       "interface needs a login: give --hmi-users"),
])
def test_a_bad_address_is_refused(capsys: pytest.CaptureFixture, tmp_path: Path,
                                  scenario: Path, flag: str, expected: str) -> None:
    line = one_line(capsys, ["run", str(scenario), "--hmi", flag, "--out", str(tmp_path / "o")])
    assert line.startswith(f"cosim run: error: {expected}")
    assert not (tmp_path / "o").exists()


def test_a_port_in_use_is_refused(capsys: pytest.CaptureFixture, tmp_path: Path,
                                  scenario: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        line = one_line(capsys, ["run", str(scenario), "--hmi", str(port), "--out",
                                 str(tmp_path / "o")])
        view = one_line(capsys, ["view", str(tmp_path), "--hmi", str(port)])
    assert line == (f"cosim run: error: --hmi 127.0.0.1:{port}: cannot listen: "
                    "Address already in use")
    assert view.startswith(f"cosim view: error: RESULTS_DIR {tmp_path}: not a run's folder")
    assert not (tmp_path / "o").exists()


def test_users_are_a_file_of_hashes(capsys: pytest.CaptureFixture, tmp_path: Path,
                                    scenario: Path) -> None:
    users = tmp_path / "users.toml"
    assert one_line(capsys, ["run", str(scenario), "--hmi-users", str(users)]) == (
        "cosim run: error: --hmi-users: only with --hmi (the page it logs in to)")
    assert one_line(capsys, ["run", str(scenario), "--hmi", "8050", "--hmi-users",
                             str(users)]) == f"cosim run: error: --hmi-users {users}: no such file"
    users.write_text('[users.ops]\nrole = "operator"\npassword = "secret"\n')
    assert one_line(capsys, ["view", str(tmp_path), "--hmi-users", str(users)]) == (
        f"cosim view: error: {users}: users.ops.password: expected a scrypt hash (python -m "
        "cosim.hmi.users writes one), not a password")
    users.unlink()
    add = [sys.executable, "-m", "cosim.hmi.users", str(users), "ops", "operator"]
    proc = subprocess.run(add, env=env(), capture_output=True, text=True, timeout=60,
                          stdin=subprocess.DEVNULL, check=False)
    assert proc.returncode == 2 and "set $COSIM_HMI_PASSWORD" in proc.stderr
    assert not users.exists()
    proc = subprocess.run(add, env=env(COSIM_HMI_PASSWORD="s3cret"), capture_output=True,
                          text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "s3cret" not in users.read_text()
    loaded = Users.load(users)
    assert loaded.check("ops", "s3cret") == loaded.check("ops", "s3cret")
    assert loaded.check("ops", "s3cret").role == "operator"
    assert loaded.check("ops", "wrong") is None and loaded.check("nobody", "s3cret") is None


def test_view_stops_after_its_duration(capsys: pytest.CaptureFixture, tmp_path: Path,
                                       scenario: Path) -> None:
    import cosim
    from cosim.live.process import free_port

    cosim.run(scenario, out=tmp_path / "run", figure=False)
    assert main(["view", str(tmp_path / "run"), "--hmi", str(free_port()),
                 "--duration", "1"]) == 0
    err = capsys.readouterr().err
    assert "cosim view: " in err and "stopped (duration)" in err
    assert one_line(capsys, ["view", str(tmp_path / "run"), "--duration", "0"]) == (
        "cosim view: error: --duration 0.0: must be a positive number of seconds")
