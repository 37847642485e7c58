"""The operator console against a lockstep flight (no browser: a WebSocket client and HTTP):
the page and its security headers, live MJPEG with no encoding once nobody watches, the socket's
hello / state / events, keyboard flying (Y, W held moves forward, key up hovers, a dropped
socket mid-key hovers, Y back to the autopilot), refused and malformed messages, and event
hooks from Python (callbacks and ``async for``) seeing the same flight."""

from __future__ import annotations

import asyncio
import json
import math
import time
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest
from websockets.sync.client import connect

from autopilot.mission import load_mission

from .test_goal_api import Client, _fly_with_client

pytestmark = pytest.mark.serial  # real-time flights, fixed ports


def _fly_console(plan, out, script):
    """A flight with the console; Python hooks (a callback and ``async for``) watch it."""
    hooked: list = []
    iterated: list = []

    def on_api(server):
        rt = server.console.host
        rt.events.on("status", lambda e: hooked.append(e.hook))

        async def follow_commands():
            async for event in rt.events.subscribe("command"):
                iterated.append(event.hook)
        asyncio.get_running_loop().create_task(follow_commands())

    summary, result = _fly_with_client(plan, out, lambda c: script(c, c.server),
                                       console=True, on_api=on_api)
    return summary, result, hooked, iterated


class Socket:
    """The console's socket, as the page uses it."""

    def __init__(self, port: int) -> None:
        self.ws = connect(f"ws://127.0.0.1:{port}/api/console", open_timeout=10).__enter__()
        self.hello = self.next("hello")
        self.events: list[dict] = []

    def next(self, kind: str, timeout_s: float = 10.0) -> dict:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            message = json.loads(self.ws.recv(timeout=timeout_s))
            if message["type"] == "event":
                self.events.append(message)
            if message["type"] == kind:
                return message
        raise AssertionError(f"no {kind} message")

    def send(self, obj) -> None:
        self.ws.send(obj if isinstance(obj, str) else json.dumps(obj))

    def drain(self) -> None:
        while True:
            try:
                message = json.loads(self.ws.recv(timeout=0.01))
            except TimeoutError:
                return
            if message["type"] == "event":
                self.events.append(message)


def _forward(status, heading_rad: float) -> float:
    p = status["position_ned_m"]
    return p[0] * math.cos(heading_rad) + p[1] * math.sin(heading_rad)


def _hold_keys(sock: Socket, c: Client, keys: list[str], until, timeout_s: float = 60.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        sock.send({"type": "keys", "held": keys})  # renewed while held, as the page does
        status = c.call("GET", "/api/status")[1]
        if until(status):
            return status
        time.sleep(0.1)
    raise AssertionError(f"holding {keys}: condition not met; last status {status}")


def emergency_stop(sock: Socket) -> list[dict]:
    """R, confirmed: the answer says the motors stop; the events until the run ends (the
    socket closes)."""
    sock.send({"type": "action", "action": "emergency", "confirm": True})
    assert "motors stop" in sock.next("answer")["text"]
    try:
        while True:
            sock.next("event", 30)
    except Exception:  # the run ended: the socket closed
        pass
    return sock.events


def _speed(status) -> float:
    return float(np.linalg.norm(status["velocity_ned_m_s"]))


def _settled(c: Client, what: str, timeout_s: float = 60.0) -> dict:
    return c.wait(lambda s: _speed(s) < 0.15, timeout_s, what)


def test_console_video_socket_keys_and_hooks(tmp_path):
    plan = load_mission("standby")

    def script(c: Client, server):
        port = server.bound_port
        c.wait(lambda s: s["status_code"] == 3 and s["waiting_for_goals"], 60, "standby")
        # the page: one self-contained file, with headers that keep it to itself
        with urllib.request.urlopen(c.base + "/", timeout=10) as resp:
            page = resp.read().decode()
            assert "autopilot console" in page
            assert "frame-ancestors 'none'" in resp.headers["Content-Security-Policy"]
        assert "http://" not in page.replace("http://www.w3.org", "")  # nothing from elsewhere
        # video: a JPEG part with its capture time; nothing encoded once nobody watches
        with urllib.request.urlopen(c.base + "/video/front.mjpg?fps=10", timeout=10) as resp:
            assert resp.headers["Content-Type"].startswith("multipart/x-mixed-replace")
            head = b""
            while not head.endswith(b"\r\n\r\n"):
                head += resp.read(1)
            length = int(next(line.split(b":")[1] for line in head.split(b"\r\n")
                              if line.lower().startswith(b"content-length")))
            image = cv2.imdecode(np.frombuffer(resp.read(length), np.uint8), cv2.IMREAD_COLOR)
            assert image.shape == (480, 640, 3)
            assert b"X-Frame-Time" in head
        code, body = c.call("GET", "/video/nope.mjpg")
        assert code == 404
        assert "front" in body["error"]
        for fps in ("1e-300", "0.1", "nan", "61"):  # a viewer that would receive nothing
            code, body = c.call("GET", f"/video/front.mjpg?fps={fps}")
            assert code == 422, (fps, body)
        time.sleep(0.5)
        stats = c.call("GET", "/api/console/stats")[1]["video"]["front"]
        assert stats["viewers"] == 0
        time.sleep(1.0)
        assert c.call("GET", "/api/console/stats")[1]["video"]["front"]["frames_encoded"] == \
            stats["frames_encoded"]
        # a foreign page's request for the video is refused
        code, _ = c.call("GET", "/video/front.mjpg", headers={"Sec-Fetch-Site": "cross-site"})
        assert code == 403

        sock = Socket(port)
        assert sock.hello["keys"]["forward"] == "w"
        assert "orbit" in sock.hello["goal_kinds"]
        first = sock.next("state")
        assert first["values"]["status"][0].startswith("3 ")
        assert first["map"]["position_ne_m"] is not None
        # refused and malformed messages are answered, never fatal
        sock.send({"type": "action", "action": "emergency"})
        answer = sock.next("answer")
        assert not answer["ok"]
        assert "confirm" in answer["text"]
        sock.send({"type": "action", "action": "takeoff"})
        assert "manual flight only" in sock.next("answer")["text"]
        sock.send("{not json")
        assert "not JSON" in sock.next("error")["error"]
        sock.send({"type": "keys", "held": "w"})
        assert "list of axes" in sock.next("error")["error"]
        sock.send({"type": "launch"})
        assert "unknown message type" in sock.next("error")["error"]
        sock.send({"type": "action", "action": "self_destruct"})
        assert not sock.next("answer")["ok"]
        # keys while the autopilot flies: nothing moves
        before = c.call("GET", "/api/status")[1]
        for _ in range(5):
            sock.send({"type": "keys", "held": ["forward"]})
            time.sleep(0.1)
        sock.send({"type": "keys", "held": []})
        after = c.call("GET", "/api/status")[1]
        assert abs(_forward(after, 0) - _forward(before, 0)) < 0.3
        # Y: manual flight
        sock.send({"type": "action", "action": "autopilot"})
        assert sock.next("answer")["ok"]
        status = c.wait(lambda s: s["control"] == "manual", 30, "manual")
        heading = math.radians(status["yaw_deg"])
        start = _forward(status, heading)
        altitude = -status["position_ned_m"][2]
        # W held: forward; key up: it stops and hovers
        moved = _hold_keys(sock, c, ["forward"],
                           lambda s: _forward(s, heading) - start > 1.5 and _speed(s) > 0.8)
        assert abs(-moved["position_ned_m"][2] - altitude) < 0.5
        sock.send({"type": "keys", "held": []})
        stopped = _settled(c, "hover after key up")
        assert stopped["mode"] == "offboard"
        t0, p0 = stopped["time_s"], np.array(stopped["position_ned_m"])
        later = c.wait(lambda s: s["time_s"] > t0 + 2.0, 30, "2 s of hover")
        assert np.linalg.norm(np.array(later["position_ned_m"]) - p0) < 0.3
        # W held, then the socket drops mid-key: it stops (hover), still in manual
        state = sock.next("state")
        assert "control" in state["values"]
        _hold_keys(sock, c, ["forward"], lambda s: _speed(s) > 0.8)
        sock.ws.close()
        dropped_at = c.call("GET", "/api/status")[1]
        stopped = _settled(c, "hover after the socket dropped", 30)
        assert stopped["control"] == "manual"
        assert stopped["in_air"]
        assert stopped["time_s"] - dropped_at["time_s"] < 4.0
        # Y again (a new page): the autopilot takes over; the standby hovers where it is
        sock = Socket(port)
        sock.send({"type": "action", "action": "autopilot"})
        assert sock.next("answer")["ok"]
        resumed = c.wait(lambda s: s["control"] == "autopilot" and s["waiting_for_goals"], 30,
                         "autopilot again")
        t0, p0 = resumed["time_s"], np.array(resumed["position_ned_m"])
        later = c.wait(lambda s: s["time_s"] > t0 + 3.0, 30, "3 s later")
        assert np.linalg.norm(np.array(later["position_ned_m"]) - p0) < 0.5
        sock.drain()
        code, _ = c.call("POST", "/api/goals", {"land": {}})
        assert code == 202
        sock.next("state")
        events = list(sock.events)
        try:
            while True:
                events.append(sock.next("event", 30))
        except Exception:  # the run ended: the socket closed
            pass
        return events

    summary, events, hooked, iterated = _fly_console(plan, tmp_path / "run", script)
    assert summary["status"] == "completed", summary["reason"]
    names = [(e["kind"], e["name"]) for e in events]
    assert ("console", "autopilot") in names
    assert any(e["hook"] == "before_cmd_land" for e in events)
    assert any(e["kind"] == "step_ended" and e["data"]["outcome"] == "succeeded"
               for e in events)
    # Python hooks saw the same flight: callbacks and async for
    assert "on_status_hover" in hooked
    assert "on_status_landing_completed" in hooked
    assert "before_cmd_arm" in iterated
    assert "after_cmd_land" in iterated


def test_console_and_api_addresses_must_agree(tmp_path, capsys):
    from autopilot.cli import main

    assert main(["run", "--mission", "standby", "--api", "127.0.0.1:8080", "--console",
                 "127.0.0.1:8090", "--out", str(tmp_path)]) != 0
    assert "on one address" in capsys.readouterr().err
    assert main(["run", "--mission", "standby", "--console", "127.0.0.1:99999",
                 "--out", str(tmp_path)]) != 0
    assert "--console '127.0.0.1:99999': port 99999 is out of range" in capsys.readouterr().err


def test_console_manual_land_takeoff_and_emergency_stop(tmp_path):
    """L in manual flight lands (and PX4 disarms); T takes off again; Y gives the vehicle back
    (the standby hovers there). R needs confirming; then the motors stop — in the air, a
    flight termination — and the run ends aborted."""
    plan = load_mission("standby")

    def script(c: Client, server):
        c.wait(lambda s: s["status_code"] == 3 and s["waiting_for_goals"], 60, "standby")
        sock = Socket(server.bound_port)
        sock.send({"type": "action", "action": "autopilot"})
        assert sock.next("answer")["ok"]
        c.wait(lambda s: s["control"] == "manual", 30, "manual")
        sock.send({"type": "action", "action": "land"})
        assert sock.next("answer")["ok"]
        c.wait(lambda s: not s["armed"] and not s["in_air"], 90, "landed and disarmed")
        sock.send({"type": "action", "action": "takeoff"})
        assert sock.next("answer")["ok"]
        c.wait(lambda s: s["in_air"] and -s["position_ned_m"][2] > 2.5, 90, "airborne again")
        sock.send({"type": "action", "action": "autopilot"})
        assert sock.next("answer")["ok"]
        c.wait(lambda s: s["control"] == "autopilot" and s["waiting_for_goals"], 30, "standby")
        return emergency_stop(sock)

    summary, events, _, _ = _fly_console(plan, tmp_path / "run", script)
    assert summary["status"] == "aborted"
    assert "emergency stop from the console" in summary["reason"]
    hooks = [e["hook"] for e in events]
    assert "before_cmd_land" in hooks
    assert "before_cmd_takeoff" in hooks
    assert "before_cmd_disarm" in hooks
    kill = next(e for e in events if e["hook"] == "before_cmd_disarm")
    assert kill["data"]["force"] is True  # in the air: flight termination
    assert "on_disarmed" in hooks


def test_simulator_console_watches_the_vehicle():
    """``autopilot sim --console``: the simulated vehicle's own console shows its camera,
    telemetry values and messages, and does not fly it (the MAVLink client does)."""
    from autopilot.config import load_config
    from autopilot.sim_server import serve

    servers = []

    async def main():
        stop = asyncio.Event()
        sim = asyncio.ensure_future(serve(
            load_config(), None, instance=9, videos=None, log=lambda line: None, stop=stop,
            console="127.0.0.1:0", on_console=servers.append, title="test world"))
        try:
            while not servers:
                if sim.done():
                    sim.result()
                await asyncio.sleep(0.05)
            return await asyncio.to_thread(script, Client(servers[0].bound_port))
        finally:
            stop.set()
            await asyncio.wait_for(sim, 60)

    def script(c: Client):
        sock = Socket(int(c.base.rsplit(":", 1)[1]))
        assert sock.hello["can_fly"] is False
        assert sock.hello["goal_kinds"] == []
        assert "test world" in sock.hello["mission"]
        state = c.wait(lambda s: s["mode"] is not None, 30, "telemetry")
        assert state["control"] == "external"
        values = sock.next("state")["values"]
        for _ in range(20):
            if "alt_m" in values:
                break
            values = sock.next("state")["values"]
        assert "alt_m" in values
        assert "mode" in values
        sock.send({"type": "action", "action": "autopilot"})
        answer = sock.next("answer")
        assert not answer["ok"]
        assert "watches" in answer["text"]
        code, _ = c.call("POST", "/api/goals", {"land": {}})
        assert code == 409
        with urllib.request.urlopen(c.base + "/video/front.mjpg", timeout=20) as resp:
            assert resp.read(7) == b"--frame"
        return True

    assert asyncio.run(main())


def test_console_security_token_cookie_and_origins(tmp_path):
    """With a token: the page needs it (once as ?token=, then a same-site cookie per port);
    the socket needs it too; a page of another origin — another port on this very host
    included — cannot open the socket or fetch the video."""
    from websockets.exceptions import InvalidStatus, WebSocketException

    token = "t0ken-for-the-console-test"
    plan = load_mission("standby")

    def script(c: Client):
        port = int(c.base.rsplit(":", 1)[1])
        c.wait(lambda s: s["status_code"] == 3, 60, "standby")
        anonymous = Client(port)
        assert anonymous.call("GET", "/api/status")[0] == 401
        for bad in ("", "wrong-token-of-enough-length"):
            assert _open(f"{c.base}/?token={bad}")[0] == 401
        code, headers = _open(f"{c.base}/?token={token}")
        assert code == 303
        cookie = headers["Set-Cookie"]
        assert cookie.startswith(f"autopilot_token_{port}=")
        assert "HttpOnly" in cookie
        assert "SameSite=strict" in cookie or "samesite=strict" in cookie.lower()
        jar = cookie.split(";", 1)[0]
        req = urllib.request.Request(c.base + "/", headers={"Cookie": jar})
        with urllib.request.urlopen(req, timeout=10) as resp:
            assert resp.status == 200
        url = f"ws://127.0.0.1:{port}/api/console"
        refused = (InvalidStatus, WebSocketException, ConnectionError, EOFError)
        with pytest.raises(refused):
            _hello(url)  # no cookie, no token
        assert _hello(url, additional_headers={"Cookie": jar})["type"] == "hello"
        for origin in ("http://127.0.0.1:9999", "http://evil.example"):
            with pytest.raises(refused):
                _hello(url, origin=origin, additional_headers={"Cookie": jar})
        code, _ = c.call("GET", "/video/front.mjpg", headers={"Sec-Fetch-Site": "same-site"})
        assert code == 403
        c.call("POST", "/api/goals", {"land": {}})
        return True

    summary, ok = _fly_with_client(plan, tmp_path / "run", script, token=token, console=True)
    assert ok
    assert summary["status"] == "completed"


class NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *args, **kwargs):
        return None


def _open(url: str):
    """(status, headers) without following a redirect."""
    try:
        with urllib.request.build_opener(NoRedirect).open(url, timeout=10) as resp:
            return resp.status, resp.headers
    except urllib.error.HTTPError as err:
        return err.code, err.headers


def _hello(url: str, **options) -> dict:
    with connect(url, open_timeout=10, **options) as ws:
        return json.loads(ws.recv(timeout=5))


def test_a_step_flown_by_the_vehicles_own_mode_asks_for_it_again_after_manual_flight(tmp_path):
    """Manual flight leaves the vehicle in OFFBOARD; a hold step given back the vehicle asks
    for HOLD again (not left in OFFBOARD without setpoints, where the vehicle's offboard-loss
    failsafe would take over), and the mission goes on to its landing."""
    mission = tmp_path / "hold.yaml"
    mission.write_text("name: hold_then_land\ndescription: hold, then land\nsteps:\n"
                       "  - takeoff: {altitude_m: 2.0}\n  - hold: {duration_s: 8}\n"
                       "  - land: {}\nfallback: land\n")
    plan = load_mission(str(mission))

    def script(c: Client, server):
        c.wait(lambda s: s["step"] == "hold" and s["mode"] == "hold", 60, "holding")
        sock = Socket(server.bound_port)
        sock.send({"type": "action", "action": "autopilot"})
        assert sock.next("answer")["ok"]
        c.wait(lambda s: s["control"] == "manual" and s["mode"] == "offboard", 30,
               "manual, in OFFBOARD")
        _hold_keys(sock, c, ["right"], lambda s: abs(s["position_ned_m"][1]) > 1.0)
        sock.send({"type": "keys", "held": []})
        _settled(c, "hover")
        sock.send({"type": "action", "action": "autopilot"})
        assert sock.next("answer")["ok"]
        asked = sock.next("event")
        while asked["hook"] != "before_cmd_hold":  # (not the vehicle's failsafe: the step)
            assert asked["kind"] != "status_text" or "failsafe" not in asked["text"].lower()
            asked = sock.next("event")
        back = c.wait(lambda s: s["control"] == "autopilot" and s["mode"] == "hold", 30,
                      "HOLD again")
        assert back["step"] == "hold"
        return True

    summary, ok, _, _ = _fly_console(plan, tmp_path / "run", script)
    assert ok
    assert summary["status"] == "completed", summary["reason"]
