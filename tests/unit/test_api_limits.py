"""The goal API's connection limits (issue 31, item 1): idle connections beyond the caps are
closed at once, the ones within them when their headers do not come in time (slow headers
too), a WebSocket outlives that deadline, and requests are answered throughout."""

from __future__ import annotations

import asyncio
import json
import socket
import time
from types import SimpleNamespace

import pytest
from websockets.sync.client import connect

from autopilot.api_server import ApiServer, ConnectionLimits

pytestmark = pytest.mark.serial  # the API's timeouts on the wall clock

LIMITS = ConnectionLimits(max_connections=24, max_per_client=12, header_timeout_s=2.0)


def _closed(sock: socket.socket, wait_s: float) -> bool:
    sock.settimeout(wait_s)
    try:
        return sock.recv(1) == b""
    except TimeoutError:
        return False
    except OSError:  # reset
        return True


def _status(port: int) -> int:
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        return int(s.recv(64).split()[1])


def _abuse(port: int) -> dict:
    out: dict = {}
    idle = [socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(60)]
    start = time.monotonic()
    deadline = start + 1.0  # well before the header deadline
    out["closed_at_once"] = sum(_closed(s, max(0.01, deadline - time.monotonic())) for s in idle)
    out["early_s"] = time.monotonic() - start
    out["closed_after_timeout"] = sum(_closed(s, 10.0) for s in idle)
    for s in idle:
        s.close()
    out["status_after"] = _status(port)
    # slow headers: a byte every 0.2 s never finishes a request in time
    slow = socket.create_connection(("127.0.0.1", port), timeout=5)
    start = time.monotonic()
    closed = False
    for byte in b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Padding: " + b"p" * 40:
        try:
            slow.sendall(bytes([byte]))
        except OSError:
            closed = True
            break
        if _closed(slow, 0.2):
            closed = True
            break
    out["slow_closed_s"] = time.monotonic() - start if closed else None
    slow.close()
    # a WebSocket lives past the header deadline
    with connect(f"ws://127.0.0.1:{port}/api/status/stream") as ws:
        first = json.loads(ws.recv(timeout=5))
        time.sleep(LIMITS.header_timeout_s * 2)
        later = json.loads(ws.recv(timeout=5))
    out["ws"] = (first, later)
    return out


def _against_a_server(script) -> dict:
    """``script(port)`` (in a thread) against an API server with :data:`LIMITS`."""
    runtime = SimpleNamespace(api_status=lambda: {"status_code": 3}, goals=None)

    async def main():
        server = ApiServer(runtime, "127.0.0.1", 0, None, limits=LIMITS)
        task = asyncio.ensure_future(server.run())
        await server.started.wait()
        try:
            return await asyncio.to_thread(script, server.bound_port)
        finally:
            await server.stop(graceful=False)
            task.cancel()

    return asyncio.run(main())


def test_idle_and_slow_connections_are_capped_and_timed_out():
    out = _against_a_server(_abuse)
    if out["early_s"] < LIMITS.header_timeout_s:  # (a machine too busy to tell: skipped)
        assert out["closed_at_once"] >= 60 - LIMITS.max_per_client  # beyond the cap: at once
    assert out["closed_after_timeout"] == 60  # within it: at the header deadline
    assert out["status_after"] == 200
    assert out["slow_closed_s"] is not None  # before its headers were complete
    assert out["ws"][0]["status_code"] == 3
    assert out["ws"][1]["status_code"] == 3


def _from_many_addresses(port: int) -> dict:
    """Idle sockets from 12 addresses (127.0.1.x, each within its own cap) fill the server;
    a client that speaks is still answered, the longest-silent socket making room."""
    idle = [socket.create_connection(("127.0.0.1", port), timeout=5,
                                     source_address=(f"127.0.1.{1 + i % 12}", 0))
            for i in range(2 * LIMITS.max_connections)]
    time.sleep(0.3)
    answered = [_status(port) for _ in range(5)]
    closed = [_closed(s, 0.05) for s in idle]
    for s in idle:
        s.close()
    return {"answered": answered, "closed": closed}


def test_idle_sockets_from_many_addresses_do_not_lock_out_a_client_that_speaks():
    out = _against_a_server(_from_many_addresses)
    assert out["answered"] == [200] * 5
    # the oldest made room: the first ones are gone, at most the cap's worth are open
    assert out["closed"][0]
    assert sum(not c for c in out["closed"]) <= LIMITS.max_connections
