"""A small synchronous OPC UA client for the tests: read and write a served plant's
variables by browse name (a real asyncua client in its own event loop)."""

from __future__ import annotations

import asyncio
from typing import Any


def call(endpoint: str, action: Any, timeout: float = 20.0,
         folder_name: str = "fourtank") -> Any:
    """Connect anonymously, run ``await action(client, folder)`` (``folder``: the served
    problem's folder), disconnect; its result."""
    from asyncua import Client

    async def main() -> Any:
        async with Client(endpoint, timeout=5) as client:
            folder = await client.nodes.objects.get_child([f"2:{folder_name}"])
            return await action(client, folder)

    return asyncio.run(asyncio.wait_for(main(), timeout))


def write(endpoint: str, path: list[str], value: Any) -> None:
    """Write ``value`` (a float as Double, a bool as Boolean) at ``path`` below the folder."""
    from asyncua import ua

    vt = ua.VariantType.Boolean if isinstance(value, bool) else ua.VariantType.Double

    async def action(client: Any, folder: Any) -> None:
        node = await folder.get_child([f"2:{p}" for p in path])
        await node.write_value(ua.DataValue(ua.Variant(value, vt)))

    call(endpoint, action)


def read(endpoint: str, path: list[str]) -> Any:
    """The DataValue at ``path`` below the folder."""
    async def action(client: Any, folder: Any) -> Any:
        node = await folder.get_child([f"2:{p}" for p in path])
        return await node.read_data_value(raise_on_bad_status=False)

    return call(endpoint, action)
