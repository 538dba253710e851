"""``cosim serve-plant``: the address space a control system would show, the plant stepped
on the wall clock, the rehearsal switches, a clean stop (a real server in its own process)."""

from __future__ import annotations

import asyncio
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest

from tests.cosim.live import ua
from tests.cosim.live.conftest import cosim, env, free_port, served


def test_address_space(tmp_path: Path) -> None:
    from asyncua import ua as uat

    with served(tmp_path, "--security", "None", "--speed", "100") as s:
        async def browse(client: Any, folder: Any) -> dict:
            out = {}
            for node in await folder.get_children():
                name = (await node.read_browse_name()).Name
                if await node.read_node_class() != uat.NodeClass.Variable:
                    out[name] = sorted([(await c.read_browse_name()).Name
                                        for c in await node.get_children()])
                    continue
                props = {(await c.read_browse_name()).Name: await c.read_value()
                         for c in await node.get_children()}
                out[name] = {
                    "type": (await node.read_type_definition()).Identifier,
                    "writable": bool((await node.read_attribute(
                        uat.AttributeIds.UserAccessLevel)).Value.Value & 2),
                    "range": (props["EURange"].Low, props["EURange"].High),
                    "unit": props["EngineeringUnits"].DisplayName.Text,
                    "id": node.nodeid.to_string()}
            return out

        space = ua.call(s.endpoint, browse)
    analog = uat.ObjectIds.AnalogItemType
    assert space["h1"] == {"type": analog, "writable": False, "range": (0.0, 2.0), "unit": "m",
                           "id": "ns=2;s=fourtank.h1"}
    assert space["qa"] == {"type": analog, "writable": True, "range": (0.0, 9.05e-4),
                           "unit": "m3/s", "id": "ns=2;s=fourtank.qa"}
    assert space["Simulation"] == ["BadOutputs", "Frozen", "Speed", "StaleOutputs", "Time"]
    assert "gamma_a" in space["Parameters"]


def test_wall_clock_frozen_start_switches_and_clean_stop(tmp_path: Path) -> None:
    record = tmp_path / "plant.csv"
    with served(tmp_path, "--security", "None", "--speed", "250", "--frozen",
                "--record", str(record)) as s:
        t0 = ua.read(s.endpoint, ["h1"])
        time.sleep(0.35)
        t1 = ua.read(s.endpoint, ["h1"])
        # frozen: the value held, republished every sample (its source timestamp moves)
        assert t1.Value.Value == t0.Value.Value and t1.SourceTimestamp > t0.SourceTimestamp
        assert ua.read(s.endpoint, ["Simulation", "Time"]).Value.Value == 0.0
        ua.write(s.endpoint, ["qa"], 8e-4)          # a client's write thaws it
        time.sleep(0.55)
        assert ua.read(s.endpoint, ["Simulation", "Frozen"]).Value.Value is False
        h1 = ua.read(s.endpoint, ["h1"])
        assert h1.Value.Value > t0.Value.Value                          # qa fills tank 1
        ua.write(s.endpoint, ["Simulation", "BadOutputs"], True)
        time.sleep(0.25)
        assert ua.read(s.endpoint, ["h1"]).StatusCode.name == "BadSensorFailure"
        ua.write(s.endpoint, ["Simulation", "BadOutputs"], False)
        ua.write(s.endpoint, ["Simulation", "StaleOutputs"], True)
        time.sleep(0.25)
        a = ua.read(s.endpoint, ["h1"])
        time.sleep(0.25)
        assert ua.read(s.endpoint, ["h1"]).SourceTimestamp == a.SourceTimestamp
        ua.write(s.endpoint, ["qa"], 5.0)                               # outside the box
        time.sleep(0.25)
        assert s.stop() == 0
    err = s.stderr()
    assert "stopped (SIGTERM)" in err and "clipped" in err and "Traceback" not in err
    rows = [list(map(float, line.split(","))) for line in record.read_text().splitlines()[1:]]
    times = [r[0] for r in rows]
    assert times == [25.0 * k for k in range(len(rows))] and len(rows) >= 8
    assert {r[1] for r in rows} <= {8e-4, 9.05e-4}      # as written, then clipped
    assert rows[-1][1] == 9.05e-4


def test_bad_input_one_line(tmp_path: Path) -> None:
    port = free_port()
    for args, words in ((["--speed", "0"], "--speed 0.0: must be a positive number"),
                        (["--endpoint", "http://x"], "--endpoint http://x: expected opc.tcp"),
                        ([], "--security: required")):
        r = subprocess.run(cosim("serve-plant", "--security", "None", *args) if args
                           else cosim("serve-plant", "--endpoint", f"opc.tcp://127.0.0.1:{port}"),
                           env=env(), cwd=tmp_path, capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and words in r.stderr and len(r.stderr.splitlines()) == 1, \
            r.stderr


@pytest.mark.slow
def test_busy_port_is_one_line(tmp_path: Path) -> None:
    with served(tmp_path, "--security", "None") as s:
        r = subprocess.run(cosim("serve-plant", "--security", "None", "--endpoint", s.endpoint,
                                 "--quiet"), env=env(), cwd=tmp_path, capture_output=True,
                           text=True, timeout=60)
    assert r.returncode == 2 and "cannot listen" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_client_helper_is_bounded() -> None:
    with pytest.raises((OSError, asyncio.TimeoutError)):
        ua.read(f"opc.tcp://127.0.0.1:{free_port()}", ["h1"])
