"""The controller's OPC UA faceplate during a live rehearsal (cosim serve-plant + cosim run
--faceplate, real servers and clients on 127.0.0.1): an operator's write switches the mode
and is one row of operator.csv; a value outside the box answers BadOutOfRange, a weight
BadUserAccessDenied, each with its reason in the audit log; the predictions are readable;
a users file whose password variable is missing is bad input (exit 2, one line)."""

from __future__ import annotations

import asyncio
import csv
import subprocess
from pathlib import Path

import pytest

from tests.cosim.live.conftest import cosim, env, free_port, served

USERS = ('[users.olga]\nrole = "operator"\npassword_env = "FP_OLGA"\n'
         '[users.erik]\nrole = "engineer"\npassword_env = "FP_ERIK"\n')


async def _operate(port: int) -> dict:
    """As the operator olga: wait for the faceplate, read a prediction, switch to manual,
    write a limit outside the box and a weight (an engineer's)."""
    from asyncua import Client, ua
    from asyncua.ua.uaerrors import BadOutOfRange, BadUserAccessDenied

    client = None
    for _ in range(150):   # the run builds its controller first: up to 45 s
        try:
            client = Client(f"opc.tcp://127.0.0.1:{port}", timeout=10)
            client.set_user("olga")
            client.set_password("olga-secret")
            await client.connect()
            break
        except (TimeoutError, OSError):
            client = None
            await asyncio.sleep(0.3)
    assert client is not None, "the faceplate never listened"
    out: dict = {}
    try:
        idx = await client.get_namespace_index("urn:gru-mpc-cosim:faceplate")

        def node(name: str):
            return client.get_node(ua.NodeId(name, idx))

        await asyncio.sleep(2.0)   # a few samples
        out["predicted"] = await node("pred.h1").read_value()
        await node("op.mode").write_value(ua.DataValue(ua.Variant(0.0, ua.VariantType.Double)))
        out["mode"] = await node("op.mode").read_value()
        for name, value, error in (("op.max.qa", 5.0, BadOutOfRange),
                                   ("R.qa", 0.1, BadUserAccessDenied)):
            with pytest.raises(error):
                await node(name).write_value(
                    ua.DataValue(ua.Variant(value, ua.VariantType.Double)))
        out["limit"] = await node("op.max.qa").read_value()
    finally:
        await client.disconnect()
    return out


@pytest.mark.slow
def test_a_faceplate_write_is_checked_and_audited(tmp_path: Path) -> None:
    scenario = tmp_path / "rehearsal.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n1500,,\n")
    (tmp_path / "users.toml").write_text(USERS)
    face = free_port()
    with served(tmp_path, "--security", "None", "--speed", "40", "--frozen") as plant:
        run = subprocess.Popen(
            cosim("run", str(scenario), "--plant", plant.endpoint, "--speed", "40",
                  "--security", "None", "--faceplate", f"opc.tcp://127.0.0.1:{face}",
                  "--faceplate-users", str(tmp_path / "users.toml"), "--out",
                  str(tmp_path / "out"), "--no-figure", "--quiet"),
            env=env(FP_OLGA="olga-secret", FP_ERIK="erik-secret"), stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True)
        try:
            seen = asyncio.run(asyncio.wait_for(_operate(face), 120))
            output, _ = run.communicate(timeout=300)
        finally:
            if run.poll() is None:
                run.kill()
    assert run.returncode == 0, output
    assert seen["mode"] == 0.0 and seen["limit"] == pytest.approx(9.05e-4)
    assert len(seen["predicted"]) == 80
    rows = list(csv.DictReader((tmp_path / "out" / "operator.csv").open()))
    assert [(r["who"], r["what"], r["new"], r["result"].split(":")[0]) for r in rows] == [
        ("olga", "op.mode", "0.0", "accepted"), ("olga", "op.max.qa", "5.0", "refused"),
        ("olga", "R.qa", "0.1", "refused")]
    assert "outside [0, 0.000905] m3/s" in rows[1]["result"]
    assert "the engineer's to change" in rows[2]["result"]
    results = list(csv.DictReader((tmp_path / "out" / "results.csv").open()))
    switched = float(rows[0]["time"])
    after = [r for r in results if float(r["time"]) > switched + 30]
    assert after and len({r["plant.qa"] for r in after}) == 1   # manual: held


def test_a_missing_password_is_bad_input(tmp_path: Path) -> None:
    (tmp_path / "users.toml").write_text(USERS)
    scenario = tmp_path / "s.csv"
    scenario.write_text("time,ref.h1,ref.h2\n0,0.65,0.65\n100,,\n")
    proc = subprocess.run(cosim("run", str(scenario), "--faceplate", "opc.tcp://127.0.0.1:4999",
                                "--faceplate-users", str(tmp_path / "users.toml"), "--quiet"),
                          env=env(), capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().count("\n") == 0
    assert "[users.olga]: the environment variable FP_OLGA holding the password is not set" \
        in proc.stderr
