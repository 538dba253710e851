"""A vendor-style PLC served by a second OPC UA stack (node-opcua), in its own process, for the
live tests: ``tests/cosim/live/vendor_plc/server.js`` runs the four-tank process on the wall
clock and writes its own record of what reached it.

:func:`start_vendor_plc` starts one on a free port of 127.0.0.1 with a case (the JSON of
``vendor_plc/config.js``: units, data types, clock offset, read-time stamps, faults), waits
(bounded) for its "listening" line and returns a :class:`VendorPlc`, whose
:meth:`~VendorPlc.stop` sends SIGTERM, then SIGKILL. The ``vendor_plc`` fixture starts them
for a test (``vendor_plc(case)``) and always stops them; a test that needs one is skipped,
with one line, where Node.js or the node-opcua packages (``make node-opcua``) are missing.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from cosim.live.process import ServedPlant, free_port

__all__ = ["HEARTBEAT_ID", "VENDOR_DIR", "VendorPlc", "missing", "start_vendor_plc",
           "vendor_plc_fixture"]

#: The PLC's sources, its package.json and (installed by ``make node-opcua``) node_modules.
VENDOR_DIR = Path(__file__).resolve().parent / "vendor_plc"
#: The line the PLC prints when it listens (a JSON object follows).
LISTENING = "vendor-plc listening "
#: The tags the problem's signals are, by default (vendor_plc/config.js's DEFAULT_TAGS).
DEFAULT_IDS = {"h1": "s=PLC1.LT101.PV", "h2": "i=1002", "qa": "s=PLC1.P101.OUT",
               "qb": "i=2002"}
#: The node id of its heartbeat node, writable Int32 (below the PLC's namespace).
HEARTBEAT_ID = "s=PLC1.APC.WD"


def missing() -> str | None:
    """Why the vendor PLC cannot run here (one line), or ``None`` when it can."""
    if shutil.which("node") is None:
        return "Node.js (node) is not installed: the vendor-style PLC (node-opcua) needs it"
    if not (VENDOR_DIR / "node_modules" / "node-opcua-server" / "package.json").is_file():
        return "node-opcua is not installed (make node-opcua)"
    return None


@dataclass
class VendorPlc(ServedPlant):
    """A running vendor PLC: a live plant's server process as ``cosim serve-plant``'s is (its
    endpoint and port, its process, its log; stopped the same way), with the namespace index
    of its tags, its case and its record (CSV)."""

    namespace_index: int = 0
    case: dict = field(default_factory=dict)
    record: Path = Path()

    def stop(self, timeout: float = 10.0) -> int:
        """SIGTERM, then SIGKILL after ``timeout`` seconds; the exit status."""
        return super().stop(timeout)

    def node_id(self, signal_name: str) -> str:
        """The full node id of a signal's tag in this case (``ns=3;s=PLC1.LT101.PV``)."""
        given = self.case.get("tags", {}).get(signal_name, {}).get("id")
        return f"ns={self.namespace_index};{given or DEFAULT_IDS[signal_name]}"

    def tags_file(self, path: Path, paths: Mapping[str, str] | None = None,
                  root: str | None = "PLC1",
                  units: Mapping[str, Mapping[str, Any]] | None = None) -> Path:
        """A tags file mapping h1, h2, qa and qb onto this PLC's node ids (or onto the browse
        ``paths`` given), with ``root`` its PLC1 folder (``None``: no root); a signal in
        ``units`` gets the table form (``h1 = { node = ..., unit = "%", scale = 50.0 }``)."""
        lines = [f'root = "{self.namespace_index}:{root}"'] if root else []
        lines.append("[tags]")
        for name in ("h1", "h2", "qa", "qb"):
            tag = (paths or {}).get(name) or self.node_id(name)
            keys = (units or {}).get(name)
            if keys is None:
                lines.append(f'{name} = "{tag}"')
            else:
                lines.append(f'{name} = {{ node = "{tag}", '
                             + ", ".join(f"{k} = {json.dumps(v)}" for k, v in keys.items())
                             + " }")
        path.write_text("\n".join(lines) + "\n")
        return path

    def records(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Stop the PLC (its record is then complete); its own record: its samples (one row
        per step: ``time``, ``raw.<tag>`` as published and received, the process in SI
        units) and the writes it received (one row each: ``wall_time``, ``sample``,
        ``node``, ``type``, ``raw.<tag>``)."""
        self.stop()
        rec = pd.read_csv(self.record)
        samples = rec[rec["event"] == "sample"].reset_index(drop=True)
        writes = rec[rec["event"] == "write"].reset_index(drop=True)
        return samples, writes

    def heartbeats(self) -> pd.DataFrame:
        """Stop the PLC; the writes its heartbeat node (``PLC1/APC/WD``) received, in order
        (``wall_time``, ``sample``, ``type``, ``heartbeat``)."""
        self.stop()
        rec = pd.read_csv(self.record)
        return rec[rec["event"] == "heartbeat"].reset_index(drop=True)

    def stderr(self) -> str:
        """What the PLC printed."""
        return self.log.read_text(errors="replace")


def start_vendor_plc(tmp: Path, case: Mapping[str, Any], *, name: str = "plc",
                     wait: float = 45.0) -> VendorPlc:
    """Start the PLC for ``case`` (vendor_plc/config.js; port and record are set here) on a
    free port (another one when a process took that port first); returns once it printed its
    "listening" line.

    Raises
    ------
    RuntimeError
        It exited, or did not listen within ``wait`` seconds (then it is stopped); the
        message ends with its last line.
    """
    for attempt in range(3):
        try:
            return _launch(tmp, case, name, wait)
        except RuntimeError as exc:
            if attempt == 2 or "EADDRINUSE" not in str(exc):
                raise
    raise AssertionError("unreachable")


def _launch(tmp: Path, case: Mapping[str, Any], name: str, wait: float) -> VendorPlc:
    """One start of the PLC on a free port (:func:`start_vendor_plc`)."""
    port = free_port()
    doc = {"duration": 120, **case, "port": port, "record": str(tmp / f"{name}.csv")}
    config = tmp / f"{name}.json"
    config.write_text(json.dumps(doc))
    log = tmp / f"{name}.log"
    with log.open("w") as fh:
        proc = subprocess.Popen([str(shutil.which("node")), str(VENDOR_DIR / "server.js"),
                                 "--config", str(config)], cwd=VENDOR_DIR, stdout=fh,
                                stderr=fh, stdin=subprocess.DEVNULL, start_new_session=True)
    plc = VendorPlc("", port, proc, log, 0, dict(doc), Path(doc["record"]))
    end = time.monotonic() + wait
    while True:
        line = next((ln for ln in plc.stderr().splitlines() if ln.startswith(LISTENING)),
                    None)
        if line is not None:
            info = json.loads(line[len(LISTENING):])
            plc.endpoint, plc.namespace_index = info["endpoint"], int(info["namespace_index"])
            return plc
        exited = proc.poll()
        if exited is not None or time.monotonic() > end:
            plc.stop()
            lines = plc.stderr().strip().splitlines()
            what = (f"exited {exited} before it listened" if exited is not None
                    else f"did not listen within {wait:g} s")
            raise RuntimeError(f"the vendor PLC {what}: "
                               f"{lines[-1] if lines else '(nothing printed)'}")
        time.sleep(0.05)


@pytest.fixture(name="vendor_plc")
def vendor_plc_fixture(tmp_path: Path) -> Iterator[Callable[..., VendorPlc]]:
    """Start vendor PLCs (``vendor_plc(case, name=...)``) for the test; every one is stopped
    after it, however it ends. Skips the test (one line) without Node.js or node-opcua."""
    why = missing()
    if why is not None:
        pytest.skip(why)
    started: list[VendorPlc] = []

    def start(case: Mapping[str, Any], name: str = "plc") -> VendorPlc:
        plc = start_vendor_plc(tmp_path, case, name=name)
        started.append(plc)
        return plc

    try:
        yield start
    finally:
        for plc in started:
            plc.stop()
