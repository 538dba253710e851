"""Security a plant asks for: a signed and encrypted connection, certificates checked against
trust lists, a user whose password never appears; a refusal is one line, exit 2, and nothing
reaches the plant. The tests make their own certificates."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pandas as pd
import pytest

from cosim.live import security
from cosim.live.server import APPLICATION_URI as PLANT_URI
from cosim.live.session import APPLICATION_URI as CLIENT_URI
from tests.cosim.live.conftest import cosim, env, served

POLICY = "Basic256Sha256,SignAndEncrypt"


@pytest.mark.slow
def test_secured_run_and_its_refusals(tmp_path: Path, short_scenario: Path) -> None:
    certs = tmp_path / "certs"
    plant = security.make_certificate(certs / "plant", "plant", PLANT_URI, server=True)
    client = security.make_certificate(certs / "client", "client", CLIENT_URI, server=False)
    impostor = security.make_certificate(certs / "impostor", "impostor", PLANT_URI,
                                         server=True)
    record = tmp_path / "plant.csv"
    secret = "correct horse battery"
    with served(tmp_path, "--speed", "250", "--frozen", "--record", str(record),
                "--security", POLICY, "--certificate", str(plant[0]), "--private-key",
                str(plant[1]), "--trust", str(certs / "client"), "--user", "operator",
                extra_env={security.PASSWORD_ENV: secret}) as s:
        def run(password: str, trust: Path, out: str, *extra: str) -> subprocess.CompletedProcess:
            return subprocess.run(
                cosim("run", str(short_scenario), "--plant", s.endpoint, "--speed", "250",
                      "--security", POLICY, "--certificate", str(client[0]), "--private-key",
                      str(client[1]), "--trust", str(trust), "--user", "operator",
                      "--out", str(tmp_path / out), *extra),
                env=env(**{security.PASSWORD_ENV: password}), cwd=tmp_path,
                capture_output=True, text=True, timeout=120)

        wrong = run("guess", plant[0], "wrong")
        untrusted = run(secret, impostor[0], "untrusted")
        unsecured = subprocess.run(
            cosim("run", str(short_scenario), "--plant", s.endpoint, "--security", "None",
                  "--out", str(tmp_path / "unsecured")),
            env=env(), cwd=tmp_path, capture_output=True, text=True, timeout=120)
        good = run(secret, plant[0], "good", "--quiet")
    for r, words in ((wrong, "the server refused user 'operator' (wrong user or password)"),
                     (untrusted, "the server's certificate is not trusted"),
                     (unsecured, "offers no endpoint with security None")):
        lines = [line for line in r.stderr.splitlines() if "warning: no security" not in line]
        assert r.returncode == 2 and len(lines) == 1 and words in lines[0], r.stderr
    for name in ("wrong", "untrusted", "unsecured"):
        assert not (tmp_path / name).exists()
    assert good.returncode == 0, good.stderr
    # nothing reached the plant before the good run: it stayed frozen at its start until then
    rows = pd.read_csv(record)
    assert rows["time"].iloc[0] == 0.0 and len(rows) >= 60
    summary = (tmp_path / "good" / "summary.json").read_text()
    assert f"{POLICY}, user 'operator'" in summary
    for text in (summary, good.stderr, (tmp_path / "good" / "results.csv").read_text(),
                 (tmp_path / "good" / "controller.json").read_text(), s.stderr()):
        assert secret not in text


def test_serve_plant_refuses_a_policy_without_certificates(tmp_path: Path) -> None:
    r = subprocess.run(cosim("serve-plant", "--security", POLICY), env=env(), cwd=tmp_path,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.strip() == (
        f"cosim serve-plant: error: --certificate: required with --security {POLICY}")
