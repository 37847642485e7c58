"""The goal API (seed 004's action servers) against a lockstep flight: standby, a goal accepted
(202), a second refused (409), bad goals refused naming the key (422), cancel → hover within
1 s, a land goal → landed, the run completes (the process would exit 0)."""

from __future__ import annotations

import asyncio
import json
import math
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

from autopilot.api import ApiSetupError
from autopilot.api_server import ApiServer
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.goals import GoalManager
from autopilot.mission import load_mission
from autopilot.run import fly

pytestmark = pytest.mark.serial  # real-time flights with the goal API


class Client:
    def __init__(self, port: int, token: str | None = None) -> None:
        self.base = f"http://127.0.0.1:{port}"
        self.token = token

    def call(self, method: str, path: str, body=None, content_type="application/json",
             headers: dict | None = None) -> tuple[int, object]:
        data = None if body is None else (body if isinstance(body, bytes)
                                          else json.dumps(body).encode())
        req = urllib.request.Request(self.base + path, data=data, method=method)
        if data is not None:
            req.add_header("Content-Type", content_type)
        if self.token:
            req.add_header("Authorization", f"Bearer {self.token}")
        for k, v in (headers or {}).items():
            req.add_header(k, v)
        try:
            with urllib.request.urlopen(req, timeout=10) as resp:
                return resp.status, json.loads(resp.read() or b"null")
        except urllib.error.HTTPError as err:
            return err.code, json.loads(err.read() or b"null")

    def wait(self, predicate, timeout_s: float = 60.0, what: str = "") -> dict:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            _, status = self.call("GET", "/api/status")
            if predicate(status):
                return status
            time.sleep(0.02)
        raise AssertionError(f"timed out waiting for {what}: last status {status}")


def _fly_with_client(plan, out, script, token=None, console=False, on_api=None):
    """Fly ``plan`` with the goal API (and the console) on a free port; ``script(client)``
    runs in a thread meanwhile (``client.server``: the server). Returns (summary, what the
    script returned); a script that fails aborts the flight first."""
    servers = []

    def take(server) -> None:
        servers.append(server)
        if on_api is not None:
            on_api(server)

    async def main():
        flight = asyncio.ensure_future(fly(plan, out, api="127.0.0.1:0", api_token=token,
                                           console=console, on_api=take))
        while not servers or not servers[0].started.is_set():
            if flight.done():
                return flight.result(), None
            await asyncio.sleep(0.01)
        client = Client(servers[0].bound_port, token)
        client.server = servers[0]
        try:
            result = await asyncio.to_thread(script, client)
        except BaseException:
            await asyncio.to_thread(client.call, "POST", "/api/abort")
            await flight
            raise
        return await asyncio.wait_for(flight, 300), result

    return asyncio.run(main())


def test_goal_api_flow(tmp_path):
    plan = load_mission("standby")
    seen = {}

    def script(c: Client):
        status = c.wait(lambda s: s["status_code"] == 3 and s["waiting_for_goals"], 60,
                        "standby hover")
        seen["hover"] = status
        # bad goals: refused naming the key, nothing starts
        code, body = c.call("POST", "/api/goals", {"orbit": {"center_m": [6, 0], "radius": 3}})
        assert code == 422, body
        assert body.get("problems", [{}])[0].get("key") == "orbit.radius", body
        code, body = c.call("POST", "/api/goals", {"goto": {"position_m": [1, 2]}})
        assert code == 422
        assert body["problems"][0]["key"].startswith("goto.position_m")
        code, _ = c.call("POST", "/api/goals", b"{not json")
        assert code == 422
        # hostile shapes (issue 31): 422 or 413, never a 500, the loop not held up
        code, body = c.call("POST", "/api/goals", b'{"hold": {"duration_s": Infinity}}')
        assert code == 422, body
        assert body["problems"][0]["key"] == "hold.duration_s"
        assert body["error"].count("Infinity") == 0  # the input is echoed once, in its problem
        code, body = c.call("POST", "/api/goals",
                            b'{"hover_image": {"duration_s": 5, "offset_m": [NaN, 0]}}')
        assert code == 422, body
        assert body["problems"][0]["key"].startswith("hover_image.offset_m")
        code, body = c.call("POST", "/api/goals", b"[" * 10_000 + b"]" * 10_000)
        assert code == 422, body
        assert "nest" in body["error"]
        code, body = c.call("POST", "/api/goals", b'{"hold": {"duration_s": 1, "x": "' +
                            b"a" * (100 << 10) + b'"}}')
        assert code == 413, body
        # goals beyond the plan bounds or the default geofence (issue 31): 422 naming the key
        # and the limit, before anything is planned
        for goal, key, limit in [
                ({"orbit": {"center_m": [8600, 0], "radius_m": 500, "laps": 100,
                            "altitude_m": 8}}, "orbit.laps", "max_path_m"),
                ({"survey": {"polygon_m": [[0, 0], [200, 0], [200, 200], [0, 200]],
                             "spacing_m": 0.25, "altitude_m": 10}}, "survey.spacing_m",
                 "max_path_m"),
                ({"goto": {"position_m": [10_000, 0, 8]}}, "goto.position_m",
                 "max_distance_m"),
                ({"goto": {"position_m": [5, 0, -50]}}, "goto.position_m", "min_altitude_m"),
                ({"orbit": {"center_m": [6, 0], "altitude_m": 300}}, "orbit.altitude_m",
                 "max_altitude_m")]:
            code, body = c.call("POST", "/api/goals", goal)
            assert code == 422, (goal, body)
            assert body["problems"][0]["key"] == key, body
            assert limit in body["error"], body
        code, _ = c.call("POST", "/api/goals", b"orbit", content_type="text/plain")
        assert code == 415
        code, _ = c.call("POST", "/api/goals", {"orbit": {"center_m": [6, 0]}},
                         headers={"Origin": "http://evil.example"})
        assert code == 403
        # DNS rebinding: a page at evil.example resolving to 127.0.0.1 names its own host
        code, _ = c.call("GET", "/api/status", headers={"Host": "evil.example:8080"})
        assert code == 403
        # a form a web page posts is not JSON: refused
        code, _ = c.call("POST", "/api/abort", b"x=1",
                         content_type="application/x-www-form-urlencoded")
        assert code == 415
        code, body = c.call("POST", "/api/goals", {"takeoff": {}})
        assert code == 409
        assert "already flying" in body["error"]
        # a goal is accepted, a second refused while it runs
        code, body = c.call("POST", "/api/goals", {
            "orbit": {"center_m": [6, 0], "radius_m": 3, "altitude_m": 4, "images": 0,
                      "laps": 2}})
        assert code == 202, body
        assert body["warnings"] == []  # (no photos: nothing to warn of)
        goal = body["goal_id"]
        code, body = c.call("POST", "/api/goals", {"goto": {"position_m": [0, 0, 3]}})
        assert code == 409
        assert goal in body["error"]
        c.wait(lambda s: s["status_code"] == 6 and (s["progress"] or 0) > 0.3, 60, "orbiting")
        code, body = c.call("GET", f"/api/goals/{goal}")
        assert body["state"] == "running"
        assert body["feedback"]["phase"] == "orbiting"
        code, body = c.call("POST", f"/api/goals/{goal}/cancel")
        assert code == 200
        seen["cancelled"] = c.wait(lambda s: s["status_code"] == 3, 10, "hover after cancel")
        code, body = c.call("GET", f"/api/goals/{goal}")
        assert body["state"] == "cancelled"
        code, _ = c.call("POST", f"/api/goals/{goal}/cancel")
        assert code == 409
        code, _ = c.call("GET", "/api/goals/nope")
        assert code == 404
        # land: the run ends once landed
        code, body = c.call("POST", "/api/goals", {"land": {}})
        assert code == 202
        seen["land"] = body["goal_id"]

    summary, _ = _fly_with_client(plan, tmp_path, script)
    assert summary["status"] == "completed", summary["reason"]
    goals = {g["goal_id"]: g for g in summary["goals"]}
    assert goals[seen["land"]]["state"] == "succeeded"
    hover = seen["hover"]
    assert hover["armed"] is True
    assert hover["mode"] in ("hold", "offboard")
    assert hover["position_ned_m"][2] == pytest.approx(-2.0, abs=0.3)
    for key in ("status_code", "status", "step", "goal_id", "position_ned_m",
                "velocity_ned_m_s", "yaw_deg", "armed", "mode", "battery_fraction"):
        assert key in hover
    # cancel → hover within 1 s (simulated time, from the log): status 3, and the vehicle still
    log = read_log(tmp_path / "flight.mcap")
    cancel = next(e for e in log[ch.MISSION_EVENTS] if e["kind"] == "goal_cancelled")
    hover_at = next(r["time_s"] for r in log[ch.MISSION_STATUS]
                    if r["code"] == 3 and r["time_s"] >= cancel["time_s"])
    assert hover_at - cancel["time_s"] <= 1.0
    truth = [g for g in log[ch.GROUND_TRUTH] if g["time_s"] >= cancel["time_s"]]
    still = next(g["time_s"] for g in truth  # (horizontally: the land goal follows at once)
                 if np.linalg.norm(g["vehicle_velocity_ned_m_s"][:2]) < 0.3)
    assert still - cancel["time_s"] <= 1.0
    codes = [r["code"] for r in log[ch.MISSION_STATUS]]
    assert codes[:4] == [1, 2, 3, 6]
    assert codes[-3:] == [8, 9, 9] or codes[-2:] == [8, 9]
    # the goal was logged and scored as a step
    assert {g["name"] for g in log[ch.MISSION_GOALS]} == {"orbit", "land"}
    orbit = next(s for s in summary["metrics"]["steps"] if s["name"] == "orbit")["orbit"]
    assert math.isfinite(orbit["rms_cross_track_m"])  # (truth: GNSS decimetres on top)
    assert orbit["rms_cross_track_nav_m"] <= 0.10


def test_abort_and_the_status_stream(tmp_path):
    plan = load_mission("standby")

    def script(c: Client):
        c.wait(lambda s: s["status_code"] == 3, 60, "standby hover")
        import websockets.sync.client as ws_client

        with ws_client.connect(c.base.replace("http", "ws") + "/api/status/stream") as ws:
            first = json.loads(ws.recv(timeout=5))
            t0 = time.monotonic()
            for _ in range(5):
                json.loads(ws.recv(timeout=5))
            rate = 5 / (time.monotonic() - t0)
        assert first["status_code"] == 3
        assert rate >= 4.0  # (5 Hz, on the wall clock)
        code, _ = c.call("POST", "/api/abort")
        assert code == 200
        c.wait(lambda s: s["status_code"] == 12, 10, "abort status")
        code, _body = c.call("POST", "/api/goals", {"goto": {"position_m": [1, 0, 2]}})
        assert code == 409

    summary, _ = _fly_with_client(plan, tmp_path, script)
    assert summary["status"] == "aborted"
    assert summary["mission_status"] == 12
    log = read_log(tmp_path / "flight.mcap")
    last = log[ch.VEHICLE_STATE][-1]
    assert last["armed"] is False  # held, landed, disarmed


def test_a_token_is_needed_off_loopback_and_checked_when_given(tmp_path):
    plan = load_mission("standby")

    class FakeRuntime:
        goals = GoalManager(plan.config)

    with pytest.raises(ApiSetupError, match="token"):
        ApiServer(FakeRuntime(), "0.0.0.0", 0, None)

    def script(c: Client):
        c.wait(lambda s: s["status_code"] == 3, 60, "standby hover")
        anonymous = Client(int(c.base.rsplit(":", 1)[1]))
        assert anonymous.call("GET", "/api/status")[0] == 401
        wrong = Client(int(c.base.rsplit(":", 1)[1]), "x" * 32)
        assert wrong.call("POST", "/api/abort")[0] == 401
        assert c.call("POST", "/api/goals", {"land": {}})[0] == 202

    summary, _ = _fly_with_client(plan, tmp_path, script, token="s3cret-token-0123456789")
    assert summary["status"] == "completed"
