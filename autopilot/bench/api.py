"""``autopilot bench api``: what the goal API costs the autopilot's process, and what abuse
does to the flight (``--abuse``).

Two real-time flights of ``missions/standby.yaml`` in the simulator, hovering for the same wall
time: one with the API served and nobody asking, one with clients busy — one polling
``GET /api/status`` at ``--poll-hz`` and one following ``WS /api/status/stream`` (5 Hz), in a
process of their own. The autopilot process's CPU time over the hover (the simulator included,
which is the same in both) and the event loop's lag (how late a 10 ms timer fires, p99) are
compared: the difference is the API's cost. Requests are timed from the client (round trip on
loopback).

``--abuse`` (:func:`run_abuse`): one real-time standby hover with the console and a token, and
an attacker in a process of its own on loopback — idle sockets from many source addresses
(127.0.1.x) up to ``--idle`` at once, slow headers, bodies of 8 MB and JSON nested 10,000 deep,
requests without the token — while a client with the token keeps asking for the status, then
the largest goals the bounds accept (an orbit, a survey, a goto to the fence) and a flood of
goals. For each phase: the event loop's lag (a 10 ms timer in the autopilot's loop, p99 and
worst), what the attacker got, how many of the client's requests were answered; at the end,
whether the flight went on (never an abort; a land goal completes the run).
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import tempfile
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path

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


# ------------------------------------------------------------------------------------------
# Abuse
# ------------------------------------------------------------------------------------------

_IDLE_SOURCES = 100  # 127.0.1.1 …: within the per-address cap, not the total


def _closed_now(sock, wait_s: float = 0.0) -> bool:
    import select

    try:
        poller = select.poll()  # (select() takes no descriptor above 1,023)
        poller.register(sock, select.POLLIN | select.POLLERR | select.POLLHUP)
        return bool(poller.poll(wait_s * 1e3)) and sock.recv(1) == b""
    except OSError:
        return True


def _attack(port: int, token: str, kind: str, n: int, hold_s: float) -> dict:
    """One attack from the attacker's process (``token``: only a careless program that has
    it floods goals and sends bodies with it)."""
    import socket

    out: dict = {"attack": kind}
    if kind == "idle":  # sockets that never send a byte, from many addresses
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(max(soft, n + 256), hard), hard))
        socks, failed = [], 0
        started = time.monotonic()
        for i in range(n):
            try:
                socks.append(socket.create_connection(
                    ("127.0.0.1", port), timeout=30,
                    source_address=(f"127.0.1.{1 + i % _IDLE_SOURCES}", 0)))
            except OSError:
                failed += 1
        out["connect_s"] = round(time.monotonic() - started, 1)
        time.sleep(1.0)
        out.update(opened=len(socks), connect_failed=failed,
                   open_after_1s=sum(not _closed_now(s) for s in socks))
        time.sleep(max(hold_s - 1.0, 0.0))
        out["open_at_end"] = sum(not _closed_now(s) for s in socks)
        for s in socks:
            s.close()
    elif kind == "slow_headers":  # a header byte a second from each of n sockets
        socks = [socket.create_connection(("127.0.0.1", port), timeout=5,
                                          source_address=(f"127.0.2.{1 + i % 50}", 0))
                 for i in range(n)]
        started = time.monotonic()
        closed_at: dict[int, float] = {}
        request = b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: " + b"s" * 200
        k = 0
        while len(closed_at) < len(socks) and time.monotonic() - started < hold_s:
            for i, s in enumerate(socks):
                if i in closed_at:
                    continue
                try:
                    s.sendall(request[k:k + 1])
                    if _closed_now(s):
                        closed_at[i] = time.monotonic() - started
                except OSError:
                    closed_at[i] = time.monotonic() - started
            k += 1
            time.sleep(1.0)
        out.update(sockets=len(socks), closed=len(closed_at),
                   closed_after_s_max=max(closed_at.values()) if closed_at else None)
        for s in socks:
            s.close()
    elif kind == "bodies":  # oversized and deep bodies, with the token and without
        big = b'{"hold": {"x": "' + b"a" * (8 << 20) + b'"}}'
        deep = b"[" * 10_000 + b"]" * 10_000
        bodies = {"8MB": (big, token), "deep": (deep, token),
                  "8MB wrong token": (big, "wrong-token-0000000000"),
                  "land, no token": (b'{"land": {}}', None)}
        codes: dict[str, list[int]] = {name: [] for name in bodies}
        for _ in range(n):
            for name, (body, key) in bodies.items():
                req = urllib.request.Request(
                    f"http://127.0.0.1:{port}/api/goals", method="POST", data=body,
                    headers={"Content-Type": "application/json",
                             **({"Authorization": f"Bearer {key}"} if key else {})})
                try:
                    with urllib.request.urlopen(req, timeout=30) as r:
                        codes[name].append(r.status)
                except urllib.error.HTTPError as err:
                    codes[name].append(err.code)
                except OSError:
                    codes[name].append(0)  # the server closed it (a body beyond the limit)
        out["codes"] = {k: sorted(set(v)) for k, v in codes.items()}
        out["requests"] = n * len(bodies)
    elif kind == "flood":  # goals posted back to back by 8 threads, with the token
        from concurrent.futures import ThreadPoolExecutor

        goal = json.dumps({"goto": {"position_m": [3, 0, 3]}}).encode()

        def post(_) -> int:
            req = urllib.request.Request(
                f"http://127.0.0.1:{port}/api/goals", method="POST", data=goal,
                headers={"Content-Type": "application/json",
                         "Authorization": f"Bearer {token}"})
            try:
                with urllib.request.urlopen(req, timeout=30) as r:
                    return r.status
            except urllib.error.HTTPError as err:
                return err.code
            except OSError:
                return 0

        started = time.monotonic()
        with ThreadPoolExecutor(8) as pool:
            codes = list(pool.map(post, range(n)))
        out.update(codes={str(c): codes.count(c) for c in sorted(set(codes))},
                   per_s=round(n / (time.monotonic() - started)))
    return out


def _attacker(port: int, token: str, commands, results) -> None:
    for kind, n, hold_s in iter(commands.get, None):
        try:
            results.put(_attack(port, token, kind, n, hold_s))
        except Exception as exc:  # the bench reports it; the attacker goes on
            results.put({"attack": kind, "error": f"{type(exc).__name__}: {exc}"})


class _Client:
    """The operator's client, with the token (in the bench's process, off the loop)."""

    def __init__(self, port: int, token: str) -> None:
        self.base, self.token = f"http://127.0.0.1:{port}", token

    def call(self, method: str, path: str, body=None, timeout_s: float = 5.0):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method, headers={
            "Authorization": f"Bearer {self.token}",
            **({"Content-Type": "application/json"} if data is not None else {})})
        try:
            with urllib.request.urlopen(req, timeout=timeout_s) as r:
                return r.status, json.loads(r.read() or b"null")
        except urllib.error.HTTPError as err:
            return err.code, json.loads(err.read() or b"null")
        except OSError as err:
            return 0, {"error": str(err)}


def largest_goals(config) -> list[tuple[str, dict]]:
    """The largest goals the default bounds accept, from a hover over home: an orbit of as many
    laps as control.trajectory.max_path_m allows, a survey whose lines, turns and photos come
    to just under max_path_m and max_photos, and a goto to just inside the fence."""
    import math

    t, gf = config.control.trajectory, config.failsafe.geofence
    radius = 50.0
    laps = math.floor((t.max_path_m * 0.97 - 2 * radius) / (2 * math.pi * radius))
    side = 100.0
    spacing = round(side * side / (t.max_path_m * 0.85), 2)
    photo = max(5.0, round(side * side / spacing / (t.max_photos * 0.8), 1))
    reach = (gf.max_distance_m or 500.0) - 1.0
    return [
        ("orbit", {"orbit": {"center_m": [0, radius + 10], "radius_m": radius, "laps": laps,
                             "altitude_m": 10, "speed_m_s": 5, "images": 100}}),
        ("survey", {"survey": {"polygon_m": [[0, 0], [side, 0], [side, side], [0, side]],
                               "spacing_m": spacing, "photo_spacing_m": photo,
                               "altitude_m": 10}}),
        ("goto", {"goto": {"position_m": [reach, 0, 10], "speed_m_s": 10}}),
    ]


def run_abuse(idle: int = 2000, hold_s: float = 12.0, flood: int = 500,
              log: Callable[[str], None] = lambda message: None) -> dict:
    import secrets

    plan = load_mission("standby")
    token = secrets.token_urlsafe(24)
    servers: list = []
    phases: list[dict] = []
    out: dict = {"bench": "api-abuse", "idle": idle, "hold_s": hold_s, "flood": flood}

    async def main() -> None:
        flight = asyncio.ensure_future(fly(plan, Path(folder), realtime=True,
                                           api="127.0.0.1:0", api_token=token, console=True,
                                           on_api=servers.append))
        while not servers or not servers[0].started.is_set():
            if flight.done():
                raise RuntimeError(f"the flight ended before its API started: "
                                   f"{flight.result()}")
            await asyncio.sleep(0.05)
        client = _Client(servers[0].bound_port, token)
        lags: list[tuple[float, float]] = []
        statuses: list[tuple[float, int]] = []
        stop = asyncio.Event()

        async def lag_probe() -> None:
            while not stop.is_set():
                t = time.perf_counter()
                await asyncio.sleep(0.01)
                lags.append((t, (time.perf_counter() - t - 0.01) * 1e3))

        def status_code() -> int:
            code, body = client.call("GET", "/api/status", timeout_s=2.0)
            return body.get("status_code", -1) if code == 200 else -code

        async def watch() -> None:  # the operator's client, twice a second
            while not stop.is_set():
                statuses.append((time.perf_counter(), await asyncio.to_thread(status_code)))
                await asyncio.sleep(0.5)

        probe, watcher = asyncio.ensure_future(lag_probe()), asyncio.ensure_future(watch())
        while (await asyncio.to_thread(status_code)) != 3:  # noqa: ASYNC110
            await asyncio.sleep(0.2)
        spawn = multiprocessing.get_context("spawn")
        commands, results = spawn.Queue(), spawn.Queue()
        attacker = spawn.Process(target=_attacker, args=(servers[0].bound_port, token,
                                                         commands, results), daemon=True)
        attacker.start()

        def phase(name: str, started: float, extra: dict) -> None:
            ended = time.perf_counter()
            mine = [lag for t, lag in lags if started <= t <= ended]
            asked = [code for t, code in statuses if started <= t <= ended]
            phases.append({
                "phase": name, "seconds": round(ended - started, 1),
                "loop_lag_ms_p99": float(np.percentile(mine, 99)) if mine else None,
                "loop_lag_ms_max": max(mine) if mine else None,
                "status_answered": sum(c >= 0 for c in asked), "status_asked": len(asked),
                "status_codes": sorted({c for c in asked if c >= 0}), **extra})
            log(f"  {name}: loop lag p99 {phases[-1]['loop_lag_ms_p99']:.1f} ms, max "
                f"{phases[-1]['loop_lag_ms_max']:.1f} ms; status answered "
                f"{phases[-1]['status_answered']}/{len(asked)}; {extra}")

        started = time.perf_counter()
        await asyncio.sleep(hold_s)
        phase("quiet", started, {})
        for kind, n in (("idle", idle), ("slow_headers", 200), ("bodies", 3)):
            log(f"attack: {kind} …")
            started = time.perf_counter()
            commands.put((kind, n, hold_s))
            result = await asyncio.to_thread(results.get, True, hold_s * 4 + 120)
            phase(kind, started, {"attacker": result})
        for name, goal in largest_goals(plan.config):
            log(f"largest accepted {name} …")
            started = time.perf_counter()
            code, body = await asyncio.to_thread(client.call, "POST", "/api/goals", goal)
            planned_s = None
            if code == 202:
                gid = body["goal_id"]
                t0 = time.perf_counter()
                while True:  # queued, then planning (a worker), then flying
                    _, g = await asyncio.to_thread(client.call, "GET", f"/api/goals/{gid}")
                    if g.get("state") not in ("queued", "running") or \
                            g.get("feedback", {}).get("phase") not in ("", "planning"):
                        break
                    await asyncio.sleep(0.05)
                planned_s = time.perf_counter() - t0
                await asyncio.sleep(3.0)  # on its way
                _, g = await asyncio.to_thread(client.call, "GET", f"/api/goals/{gid}")
                state = g.get("state")
                await asyncio.to_thread(client.call, "POST", f"/api/goals/{gid}/cancel")
                while (await asyncio.to_thread(status_code)) != 3:  # noqa: ASYNC110
                    await asyncio.sleep(0.1)
            phase(f"largest {name}", started, {
                "accepted": code, "goal": goal, "planned_within_s": planned_s,
                "state_after_3s": state if code == 202 else body})
        log(f"goal flood: {flood} …")
        started = time.perf_counter()
        commands.put(("flood", flood, hold_s))
        result = await asyncio.to_thread(results.get, True, 600)
        codes = result
        for g in (await asyncio.to_thread(client.call, "GET", "/api/goals"))[1] or []:
            if g.get("state") in ("queued", "running"):
                await asyncio.to_thread(client.call, "POST",
                                        f"/api/goals/{g['goal_id']}/cancel")
        while (await asyncio.to_thread(status_code)) != 3:  # noqa: ASYNC110
            await asyncio.sleep(0.1)
        phase("goal flood", started, {"attacker": codes})
        commands.put(None)
        await asyncio.to_thread(attacker.join, 10)
        code, _ = await asyncio.to_thread(client.call, "POST", "/api/goals", {"land": {}})
        summary = await flight
        stop.set()
        await asyncio.gather(probe, watcher, return_exceptions=True)
        out.update(status=summary["status"], reason=summary.get("reason", ""),
                   aborted=any(c == 12 for _, c in statuses), land_goal=code,
                   phases=phases, watchdog=summary.get("timing", {}))

    with tempfile.TemporaryDirectory(prefix="bench-api-") as folder:  # (a log, as a run has)
        asyncio.run(main())
    return out


def format_abuse(result: dict) -> str:
    lines = [f"goal API abuse, real-time standby with the console and a token "
             f"(idle sockets {result['idle']}, hold {result['hold_s']:g} s):",
             "| phase | loop lag p99 / max (ms) | status answered | what happened |",
             "| --- | --- | --- | --- |"]
    for p in result["phases"]:
        what = {k: v for k, v in p.items() if k not in (
            "phase", "seconds", "loop_lag_ms_p99", "loop_lag_ms_max", "status_answered",
            "status_asked", "status_codes", "goal")}
        lines.append(f"| {p['phase']} | {p['loop_lag_ms_p99']:.1f} / {p['loop_lag_ms_max']:.1f}"
                     f" | {p['status_answered']}/{p['status_asked']} | "
                     f"{json.dumps(what, default=str)} |")
    lines.append(f"flight: {result['status']} ({result['reason'] or 'no failsafe'}); "
                 f"aborted during the attacks: {result['aborted']}")
    return "\n".join(lines)
