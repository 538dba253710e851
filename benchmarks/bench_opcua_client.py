"""The OPC UA client's share of a live sample: one Read of the measurements and one Write of the
inputs, by asyncua as ``cosim run`` uses it today, by asyncua used leaner, and by o6
(open62541) (issue 60, goal 7).

Each sample reads every output (and measured disturbance) in ONE Read service call and writes
every input in ONE Write call, against ``cosim serve-plant`` (asyncua's server, its own
process) and, where node-opcua is installed (``make node-opcua``), the vendor-style PLC of the
live tests (node-opcua's server). The clients, each with its own session, take their turns in
each round (the order rotates), so that a loaded machine weighs on all of them alike:

==================  =========================================================================
session             ``cosim.live.session.PlantSession``, as ``cosim run`` uses it: Read by
                    ``read_attributes``, Write by ``write_values``, each a hop into the
                    session's event-loop thread, with its freshness checks
asyncua-prebuilt    asyncua with the Read and Write parameters built once (only the written
                    values change), sent by ``client.uaclient.read``/``write``, same hop
asyncua-inline      the same on an event loop of the calling thread (no hop)
o6                  o6's synchronous client: ``client.read(ids, valueOnly=False)``,
                    ``client.write({id: value})`` (its own worker thread)
o6-prebuilt         o6 with a ReadRequest and WriteRequest built once
                    (``serviceRead``/``serviceWrite``)
==================  =========================================================================

Every client turns what it read into the same answer (values, every status Good, newest
source time); the answers of the clients in a round must agree, and each client's write is
read back by another. Printed per server: read, write and read + write latency (median, p99),
each client's speed-up over ``session`` measured in the same run (its time over the
client's), and the CPU time of this (the clients') process per sample. ``--security
POLICY,MODE`` secures every connection (certificates made for the run, the user ``bench``, its
password from ``$COSIM_OPCUA_PASSWORD``); ``--reconnect`` then restarts ``serve-plant`` on its
port and prints when each client reads again, by itself or after a ``reconnect()`` of its own.
The clients are in ``opcua_clients.py``.

o6 comes from PyPI (``pip install o6``; its free build prints a banner and ends its process
after 10 minutes): it is used where importable, or from ``.o6/`` at the repository's root
(``pip install --target .o6 o6``); without it its rows are left out.

Usage::

    .venv/bin/python benchmarks/bench_opcua_client.py [--samples 1000] [--period 0.02]
        [--servers serve-plant,vendor] [--clients session,asyncua-prebuilt,...]
        [--security Basic256Sha256,SignAndEncrypt] [--reconnect]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from opcua_clients import (  # noqa: E402 - the module beside this one
    READS,
    START,
    USER,
    WRITES,
    AsyncuaPrebuilt,
    Plant,
    clients_for,
)


# -- servers ---------------------------------------------------------------------------------
def security_for(tmp: Path, policy: str | None) -> tuple[Any, list[str]]:
    """The client's security and the server's options (certificates made in ``tmp``)."""
    from cosim.live import security
    from cosim.live.server import APPLICATION_URI as PLANT_URI
    from cosim.live.session import APPLICATION_URI as CLIENT_URI

    if policy is None:
        return security.Security(), ["--security", "None"]
    plant = security.make_certificate(tmp / "plant", "plant", PLANT_URI, server=True)
    client = security.make_certificate(tmp / "client", "client", CLIENT_URI, server=False)
    name, mode = policy.split(",")
    sec = security.Security(policy=name, mode=mode, certificate=client[0],
                            private_key=client[1], trust=(plant[0],), user=USER,
                            password=os.environ[security.PASSWORD_ENV])
    return sec, ["--security", policy, "--certificate", str(plant[0]), "--private-key",
                 str(plant[1]), "--trust", str(client[0]), "--user", USER]


def serve_plant(tmp: Path, policy: str | None) -> Plant:
    """``cosim serve-plant`` at speed 1 (a sample every 25 s: the values hold in a round)."""
    from cosim.live.process import start_served_plant

    sec, options = security_for(tmp, policy)
    current = []

    def start(port: int | None = None) -> Any:
        if current:
            current.pop().stop()
        current.append(start_served_plant(*options, "--speed", "1", "--quiet", port=port,
                                          log=tmp / f"serve{len(current)}.log",
                                          env=dict(os.environ, PYTHONPATH=str(ROOT))))
        return current[-1]

    served = start()
    ids = {s: f"ns=2;s=fourtank.{s}" for s in (*READS, *WRITES)}
    return Plant("cosim serve-plant (asyncua server)", served.endpoint, ids, sec,
                 ((2, "fourtank"),), lambda: current and current[-1].stop(),
                 restart=lambda: start(served.port))


def vendor(tmp: Path, policy: str | None) -> Plant | None:
    """The vendor-style PLC (node-opcua) at speed 1; ``None`` without node-opcua or when
    security is asked (it serves None only)."""
    from tests.cosim.live.vendor import missing, start_vendor_plc

    if missing() is not None or policy is not None:
        return None
    plc = start_vendor_plc(tmp, {"speed": 1, "duration": 900}, name="vendor")
    ids = {s: plc.node_id(s) for s in (*READS, *WRITES)}
    sec, _ = security_for(tmp, None)
    return Plant("vendor PLC (node-opcua server)", plc.endpoint, ids, sec,
                 ((plc.namespace_index, "PLC1"),), plc.stop)


# -- measuring -------------------------------------------------------------------------------
def measure(clients: list[Any], samples: int, period: float,
            warmup: int = 20) -> tuple[dict[str, np.ndarray], int]:
    """Rounds of read then write by every client in turn (the order rotating), one round
    every ``period`` seconds; each client's read and write latencies and the CPU time of
    this process over both [ms] per sample, and the rounds whose answers disagreed."""
    lat = {c.name: [] for c in clients}
    disagree = 0
    step = np.array([9.05e-4, 11.1e-4]) / 1000
    start = time.perf_counter()
    for i in range(warmup + samples):
        n = i % len(clients)
        answers = []
        for j, client in enumerate(clients[n:] + clients[:n]):
            u = tuple(START[s] + step[k] * ((i + j) % 7) for k, s in enumerate(WRITES))
            c0, t0 = time.process_time(), time.perf_counter()
            answer = client.read()
            t1 = time.perf_counter()
            client.write(u)
            t2, c2 = time.perf_counter(), time.process_time()
            answers.append(answer)
            if i >= warmup:
                lat[client.name].append((1e3 * (t1 - t0), 1e3 * (t2 - t1), 1e3 * (c2 - c0)))
        if not all(a.good for a in answers):
            raise SystemExit(f"a read brought a status that is not Good: {answers}")
        disagree += len({a.values for a in answers}) > 1
        wait = start + (i + 1) * period - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    return {k: np.array(v) for k, v in lat.items()}, disagree


def check_writes(clients: list[Any], plant: Plant) -> None:
    """Each client's write, read back by another session (raises when one is not there)."""
    probe = AsyncuaPrebuilt(plant, inline=True, reads=WRITES)
    try:
        for k, client in enumerate(clients):
            u = (START["qa"] * (1 + 0.01 * (k + 1)), START["qb"] * (1 - 0.01 * (k + 1)))
            client.write(u)
            got = probe.read().values
            if got != u:
                raise SystemExit(f"{client.name} wrote {u}, the server holds {got}")
    finally:
        probe.close()


def reconnection(clients: list[Any], restart: Callable[[], Any], limit: float = 15.0) -> None:
    """Stop the server and start it again on the same port: when each client reads again by
    itself (its library or session reconnecting), else after a reconnect() of its own."""
    t0 = time.perf_counter()
    restart()
    listening = time.perf_counter()
    print(f"  server restarted on its port: listening again {listening - t0:.2f} s after it "
          "stopped")
    back: dict[str, float] = {}
    while len(back) < len(clients) and time.perf_counter() - listening < limit:
        for client in clients:
            if client.name not in back and reads(client):
                back[client.name] = time.perf_counter() - listening
        time.sleep(0.05)
    for client in clients:
        if client.name in back:
            print(f"  {client.name:<17} reads again by itself {back[client.name]:.2f} s after "
                  "the server listens again")
            continue
        t = time.perf_counter()
        client.reconnect()
        print(f"  {client.name:<17} not by itself within {limit:g} s; a reconnect() of its "
              f"own: " + (f"reads again after {time.perf_counter() - t:.2f} s"
                          if reads(client) else "still no answer"))


def reads(client: Any) -> bool:
    """Whether the client reads Good values now."""
    try:
        return client.read().good
    except Exception:
        return False


def stats(ms: np.ndarray) -> tuple[float, float]:
    return float(np.median(ms)), float(np.percentile(ms, 99))


def report(lat: dict[str, np.ndarray]) -> None:
    """Median and p99 of read, write and both, the speed-up over ``session`` (its time over
    the client's), and the client process's CPU time per sample (median)."""
    print(f"  {'client':<17} {'read med':>9} {'p99':>7} {'write med':>10} {'p99':>7} "
          f"{'r+w med':>8} {'p99':>7} {'speed-up med':>13} {'p99':>6} {'CPU med':>8}")
    both = {name: ms[:, 0] + ms[:, 1] for name, ms in lat.items()}
    base = stats(both["session"]) if "session" in both else None
    for name, ms in lat.items():
        (rm, rp), (wm, wp), (bm, bp) = stats(ms[:, 0]), stats(ms[:, 1]), stats(both[name])
        ratio = (f"{base[0] / bm:12.2f}x {base[1] / bp:5.2f}x" if base is not None
                 else f"{'':>13} {'':>6}")
        print(f"  {name:<17} {rm:7.3f}ms {rp:5.2f}ms {wm:8.3f}ms {wp:5.2f}ms {bm:6.3f}ms "
              f"{bp:5.2f}ms {ratio} {np.median(ms[:, 2]):6.3f}ms", flush=True)


def bench(plant: Plant, args: argparse.Namespace) -> None:
    """Measure every client against ``plant``; print the table (and reconnection)."""
    print(f"\n{plant.name} at {plant.endpoint}, security {plant.security.describe()}")
    clients = clients_for(plant, args.clients.split(","))
    try:
        check_writes(clients, plant)
        lat, disagree = measure(clients, args.samples, args.period)
        print(f"  {args.samples} samples, one round every {1e3 * args.period:g} ms; answers "
              f"agreed in {args.samples - disagree} of {args.samples} rounds (a plant sample "
              "between two reads of a round: the others); every write read back")
        report(lat)
        if args.reconnect and plant.restart is not None:
            reconnection(clients, plant.restart)
    finally:
        for client in clients:
            client.close()


@contextlib.contextmanager
def servers(args: argparse.Namespace, tmp: Path) -> Iterator[list[Plant]]:
    """The servers asked for, each stopped at the end."""
    policy = None if args.security == "None" else args.security
    plants: list[Plant] = []
    try:
        for name in args.servers.split(","):
            plant = serve_plant(tmp, policy) if name == "serve-plant" else vendor(tmp, policy)
            if plant is None:
                print(f"{name}: left out (node-opcua is not installed, or security was asked)")
                continue
            plants.append(plant)
        yield plants
    finally:
        for plant in plants:
            with contextlib.suppress(Exception):
                plant.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=1000, help="samples per client")
    parser.add_argument("--period", type=float, default=0.02, help="seconds per round")
    parser.add_argument("--servers", default="serve-plant,vendor")
    parser.add_argument("--clients", default="session,asyncua-prebuilt,asyncua-inline,o6,"
                        "o6-prebuilt")
    parser.add_argument("--security", default="None", help="None or POLICY,MODE (then the "
                        "user 'bench' with the password in $COSIM_OPCUA_PASSWORD)")
    parser.add_argument("--reconnect", action="store_true", help="then restart serve-plant "
                        "and time each client's return")
    args = parser.parse_args()
    from cosim.live import quiet_libraries

    quiet_libraries()
    print(f"OPC UA client latency per sample: 1 Read of {len(READS)} outputs, 1 Write of "
          f"{len(WRITES)} inputs; {os.cpu_count()} CPUs, Python {sys.version.split()[0]}")
    with tempfile.TemporaryDirectory() as tmp, servers(args, Path(tmp)) as plants:
        for plant in plants:
            bench(plant, args)


if __name__ == "__main__":
    main()
