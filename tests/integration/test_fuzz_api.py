"""Fuzzing the goal API and the console's socket (Hypothesis) against a lockstep standby
flight: random JSON and bytes as goals, wrong types, unknown kinds, random paths and methods,
garbage WebSocket messages, and floods. Every answer is a 2xx/4xx, never a 500; the socket
answers and stays open; the vehicle keeps hovering and the run ends normally afterwards."""

from __future__ import annotations

import json
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from websockets.sync.client import connect

from autopilot.goals import goal_kinds
from autopilot.mission import load_mission

from ..unit.test_finite_numbers import EXAMPLES, _numeric_leaves, _replaced
from .test_goal_api import Client, _fly_with_client

pytestmark = pytest.mark.serial  # a real-time flight's goal API

json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(min_value=-(10 ** 20), max_value=10 ** 20),
              st.floats(allow_nan=False), st.text(max_size=10)),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                  max_size=4),
    max_leaves=12)
# goals: mostly shaped like one ({"KIND": {...}}), with kinds that exist and that do not
kinds = st.sampled_from(["goto", "orbit", "survey", "takeoff", "hold", "follow_ball",
                         "standby", "nope", "", "GOTO", "land_pad"])
goal_bodies = st.one_of(
    st.builds(lambda k, v: {k: v}, kinds, json_values),
    st.builds(lambda k, p: {k: p}, kinds, st.dictionaries(st.sampled_from(
        ["position_m", "center_m", "radius_m", "altitude_m", "speed_m_s", "polygon_m",
         "images", "frame", "camera", "duration_s", "x"]), json_values, max_size=4)),
    json_values)
FUZZ = settings(deadline=None)


def test_fuzzed_requests_are_answered_4xx_and_the_flight_goes_on(tmp_path):
    plan = load_mission("standby")

    def script(c: Client):
        c.wait(lambda s: s["status_code"] == 3 and s["waiting_for_goals"], 60, "standby")
        port = c.server.bound_port
        codes: set[int] = set()

        def accepted_goal_cancelled(body) -> None:
            goal_id = body["goal_id"]
            c.call("POST", f"/api/goals/{goal_id}/cancel")
            c.wait(lambda s: s["waiting_for_goals"] and s["goal_id"] is None, 60,
                   "back to standby")

        @FUZZ
        @given(goal_bodies)
        def post_goal(body):
            code, answer = c.call("POST", "/api/goals", body)
            codes.add(code)
            assert code in (202, 409, 415, 422), (body, code, answer)
            if code == 202:
                accepted_goal_cancelled(answer)

        @FUZZ
        @given(st.binary(max_size=200))
        def post_bytes(data):
            code, _ = _raw(c, "POST", "/api/goals", data, "application/json")
            codes.add(code)
            assert 400 <= code < 500, code

        @FUZZ
        @given(st.sampled_from(["GET", "POST", "PUT", "DELETE", "PATCH"]),
               st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789/._-%", max_size=30))
        def random_paths(method, path):
            code, _ = _raw(c, method, "/" + path.lstrip("/"), None, None)
            codes.add(code)
            assert code < 500, (method, path, code)

        @FUZZ
        @given(st.data(), st.sampled_from(["NaN", "Infinity", "-Infinity"]))
        def post_non_finite(data, bad):
            """NaN or ±Infinity in any number of any goal kind: 422 naming its key."""
            kind = data.draw(st.sampled_from(sorted(k for k in EXAMPLES if k in goal_kinds())))
            paths = list(_numeric_leaves(EXAMPLES[kind]))
            if not paths:
                return
            path = data.draw(st.sampled_from(paths))
            marker = 1234567.125  # a number no example holds, swapped for the bare token
            text = json.dumps({kind: _replaced(EXAMPLES[kind], path, marker)})
            code, answer = _raw(c, "POST", "/api/goals", text.replace(str(marker), bad).encode(),
                                "application/json")
            codes.add(code)
            assert code == 422, (kind, path, bad, code, answer)
            keys = [p["key"] for p in json.loads(answer)["problems"]]
            assert any(k.startswith(f"{kind}.{path[0]}") for k in keys), (path, keys)

        @FUZZ
        @given(st.integers(min_value=17, max_value=10_000), st.booleans())  # (under 64 kB)
        def post_deep(depth, objects):
            """JSON nested past the limit, or too deep to parse: 422, never a 500."""
            body = ('{"a":' * depth + "1" + "}" * depth) if objects else \
                ("[" * depth + "]" * depth)
            code, _ = _raw(c, "POST", "/api/goals", body.encode(), "application/json")
            codes.add(code)
            assert code == 422, (depth, objects, code)

        post_goal()
        post_bytes()
        post_non_finite()
        post_deep()
        random_paths()
        with connect(f"ws://127.0.0.1:{port}/api/console", open_timeout=10) as ws:
            assert json.loads(ws.recv(timeout=10))["type"] == "hello"

            @FUZZ
            @given(st.one_of(st.text(max_size=200),
                             json_values.map(json.dumps),
                             st.builds(lambda t, rest: json.dumps({"type": t, **rest}),
                                       st.sampled_from(["keys", "action", "x", ""]),
                                       st.dictionaries(st.sampled_from(
                                           ["held", "action", "confirm"]), json_values,
                                           max_size=3))))
            def socket_message(text):
                if any(word in text for word in ("emergency", "land", "autopilot")):
                    return  # (real commands: the kill switch, a landing, manual flight)
                ws.send(text)
                deadline = time.monotonic() + 5
                while time.monotonic() < deadline:
                    message = json.loads(ws.recv(timeout=5))
                    assert message["type"] in ("state", "path", "event", "answer", "error")
                    if message["type"] in ("answer", "error"):
                        return
                    if '"keys"' in text and message["type"] == "state":
                        return  # (keys are taken without an answer)

            socket_message()
            ws.send(json.dumps({"type": "keys", "held": []}))
            for _ in range(300):  # a flood of keys: taken, the loop keeps its pace
                ws.send(json.dumps({"type": "keys", "held": ["nope"]}))
        before = c.call("GET", "/api/status")[1]
        for _ in range(300):  # a flood of status requests
            assert c.call("GET", "/api/status")[0] == 200
        status = c.wait(lambda s: s["time_s"] > before["time_s"] + 1.0, 30, "time going on")
        assert status["control"] == "autopilot"
        assert status["in_air"]
        if status["waiting_for_goals"] is False:  # a fuzzed Y may have left it in manual
            c.wait(lambda s: s["waiting_for_goals"], 60, "standby")
        assert 500 not in codes
        code, _ = c.call("POST", "/api/goals", {"land": {}})
        assert code == 202
        return codes

    summary, codes = _fly_with_client(plan, tmp_path / "run", script, console=True)
    assert summary["status"] == "completed", summary["reason"]
    assert {422, 404} <= codes


def _raw(c: Client, method: str, path: str, data: bytes | None, kind: str | None):
    import urllib.error
    import urllib.request

    req = urllib.request.Request(c.base + path, data=data, method=method)
    if kind:
        req.add_header("Content-Type", kind)
    try:
        with urllib.request.urlopen(req, timeout=10) as resp:
            return resp.status, resp.read()
    except urllib.error.HTTPError as err:
        return err.code, err.read()
