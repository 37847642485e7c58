"""``autopilot bench api``: what the goal API costs the autopilot's process.

Two real-time flights of ``missions/standby.yaml`` in the simulator, hovering for the same wall
time: one with the API served and nobody asking, one with clients busy — one polling
``GET /api/status`` at ``--poll-hz`` and one following ``WS /api/status/stream`` (5 Hz), in a
process of their own. The autopilot process's CPU time over the hover (the simulator included,
which is the same in both) and the event loop's lag (how late a 10 ms timer fires, p99) are
compared: the difference is the API's cost. Requests are timed from the client (round trip on
loopback).
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import threading
import time
import urllib.request
from collections.abc import Callable

import numpy as np

from autopilot.mission import load_mission
from autopilot.run import fly


def _client(port: int, stop, poll_hz: float, results) -> None:
    """The clients, in a process of their own (their CPU is not the API's)."""
    import websockets.sync.client as ws_client

    times_ms: list[float] = []
    stream_count = [0]

    def stream() -> None:
        with ws_client.connect(f"ws://127.0.0.1:{port}/api/status/stream") as ws:
            while not stop.is_set():
                json.loads(ws.recv(timeout=5))
                stream_count[0] += 1

    follower = threading.Thread(target=stream, daemon=True)
    follower.start()
    period = 1.0 / poll_hz
    while not stop.is_set():
        started = time.perf_counter()
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=5) as r:
            json.loads(r.read())
        times_ms.append((time.perf_counter() - started) * 1e3)
        time.sleep(max(period - (time.perf_counter() - started), 0.0))
    follower.join(timeout=6)
    results.put((times_ms, stream_count[0]))


def _flight(hover_s: float, busy: bool, poll_hz: float, log: Callable[[str], None]) -> dict:
    plan = load_mission("standby")
    servers: list = []
    out: dict = {}

    async def main() -> None:
        flight = asyncio.ensure_future(fly(plan, None, realtime=True, api="127.0.0.1:0",
                                           on_api=servers.append))
        while not servers or not servers[0].started.is_set():  # noqa: ASYNC110
            await asyncio.sleep(0.05)
        port = servers[0].bound_port

        def status() -> dict:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status") as r:
                return json.loads(r.read())

        while (await asyncio.to_thread(status))["status_code"] != 3:  # noqa: ASYNC110
            await asyncio.sleep(0.2)
        lags: list[float] = []
        spawn = multiprocessing.get_context("spawn")
        stop, results = spawn.Event(), spawn.Queue()
        client = spawn.Process(target=_client, args=(port, stop, poll_hz, results),
                               daemon=True)
        times_ms: list[float] = []
        stream_count = 0
        cpu0, wall0 = time.process_time(), time.perf_counter()
        if busy:
            client.start()
        end = wall0 + hover_s
        while time.perf_counter() < end:
            t = time.perf_counter()
            await asyncio.sleep(0.01)
            lags.append((time.perf_counter() - t - 0.01) * 1e3)
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        stop.set()
        if busy:
            times_ms, stream_count = await asyncio.to_thread(results.get, True, 15)
            await asyncio.to_thread(client.join, 10)
        req = urllib.request.Request(f"http://127.0.0.1:{port}/api/goals", method="POST",
                                     data=b'{"land": {}}',
                                     headers={"Content-Type": "application/json"})
        await asyncio.to_thread(urllib.request.urlopen, req)
        summary = await flight
        out.update(cpu_share_of_one_core=cpu / wall, loop_lag_ms_p99=float(
            np.percentile(lags, 99)), requests=len(times_ms), stream_messages=stream_count,
            request_ms_p50=float(np.percentile(times_ms, 50)) if times_ms else None,
            request_ms_p99=float(np.percentile(times_ms, 99)) if times_ms else None,
            status=summary["status"])

    log(f"hovering {hover_s:g} s with the API {'busy' if busy else 'idle'} …")
    asyncio.run(main())
    return out


def run_bench(hover_s: float = 20.0, poll_hz: float = 10.0,
              log: Callable[[str], None] = lambda message: None) -> dict:
    idle = _flight(hover_s, False, poll_hz, log)
    busy = _flight(hover_s, True, poll_hz, log)
    return {"bench": "api", "hover_s": hover_s, "poll_hz": poll_hz, "idle": idle,
            "busy": busy,
            "api_cpu_share_of_one_core": busy["cpu_share_of_one_core"]
            - idle["cpu_share_of_one_core"]}


def format_table(result: dict) -> str:
    i, b = result["idle"], result["busy"]
    return "\n".join([
        f"goal API cost, standby hover {result['hover_s']:g} s in real time "
        f"(GET /api/status at {result['poll_hz']:g} Hz + the 5 Hz status stream):",
        f"  process CPU, one core: {100 * i['cpu_share_of_one_core']:.1f} % idle API, "
        f"{100 * b['cpu_share_of_one_core']:.1f} % busy → the API costs "
        f"{100 * result['api_cpu_share_of_one_core']:.1f} % of a core",
        f"  event-loop lag p99: {i['loop_lag_ms_p99']:.2f} ms idle, "
        f"{b['loop_lag_ms_p99']:.2f} ms busy",
        f"  requests: {b['requests']} (round trip p50 {b['request_ms_p50']:.1f} ms, "
        f"p99 {b['request_ms_p99']:.1f} ms), stream messages: {b['stream_messages']}"])
