"""The operator console: one page in the browser, served by the goal API's server
(:mod:`autopilot.api`), with no build step and nothing fetched from elsewhere (it works offline
in the field).

=====================================  =====================================================
``GET /``                              the page (off loopback, first a sign-in page: the
                                       token typed in becomes a same-site cookie)
``GET /video/{camera}.mjpg``           live MJPEG of a camera with the autopilot's overlays
                                       (``?fps=`` at most the configured rate;
                                       ``?overlay=0`` for the bare image)
``WS /api/console``                    pushed: ``hello`` (keys, cameras, goal kinds), then
                                       ``state`` (status, ``name::value`` board with each
                                       value's age, held keys, mini-map) at
                                       ``console.state_rate_hz``, ``path`` when the
                                       planned path changes, and every ``event``; taken:
                                       ``{"type": "keys", "held": [axis, …]}`` and
                                       ``{"type": "action", "action": …, "confirm": bool}``
``GET /api/console/stats``             what the video costs: encoded frames, CPU seconds
=====================================  =====================================================

Video: a camera is encoded only while someone watches it (no viewer, no encoding), at most
``console.video_fps`` frames a second of the wall clock, drawn and JPEG-encoded on a thread of
its own (never on the event loop). Each viewer holds only the newest encoded frame: a slow
client skips frames, it never builds a queue. The overlays are :mod:`autopilot.report.video`'s
(the same as ``onboard.mp4``), drawn over the frame the step's pipelines processed, with the
detections in that very frame.

Keys: the page re-sends the held movement keys ten times a second; the runtime lets each go
after ``console.key_timeout_s`` without renewal, so key up, a lost focus, a closed tab or a
dropped socket all end in a hover (:mod:`autopilot.behaviors.manual`).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import time
from collections.abc import AsyncIterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from importlib import resources
from typing import TYPE_CHECKING

import cv2

from autopilot.behaviors.manual import ACTIONS, AXES
from autopilot.flightlog import records as ch
from autopilot.framelog import FrameSampler
from drivers.slots import Broadcast
from drivers.threads import lower_this_thread

if TYPE_CHECKING:
    from autopilot.runtime.ports import ConsolePort

log = logging.getLogger(__name__)

BOUNDARY = "frame"


def page_html() -> str:
    return resources.files(__package__).joinpath("page.html").read_text(encoding="utf-8")


@dataclass(frozen=True, slots=True)
class JpegFrame:
    seq: int
    time_s: float  # capture time (the run's clock)
    jpeg: bytes
    age_ms: float  # capture → encoded, on the run's clock


def _draw_and_encode(image, camera_record, records, quality: int, overlay: bool
                     ) -> tuple[bytes, float]:
    """(JPEG, CPU seconds of this thread): runs on the console's thread."""
    from autopilot.report.video import draw_overlay, overlay_from

    started = time.thread_time()
    drawn = image
    if overlay:
        ov = overlay_from(records["time_s"], camera_record, records["det"], records["pose"],
                          records["est"], records["setpoint"], records["step"],
                          records["phase"])
        if records.get("manual"):
            ov = dataclasses.replace(ov, panel=(("control", "MANUAL (keys)"), *ov.panel))
        drawn = draw_overlay(image, ov)
    # (4:2:0, unlike the flight log's 4:4:4: for eyes, not for detectors; a third faster)
    ok, buffer = cv2.imencode(".jpg", drawn, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buffer.tobytes(), time.thread_time() - started


class CameraFeed:
    """One camera's live MJPEG: encodes while anyone watches; viewers take the newest."""

    def __init__(self, host: ConsolePort, camera: str, fps: float, quality: int,
                 pool: ThreadPoolExecutor, overlay: bool = True) -> None:
        self.host = host
        self.camera = camera
        self.fps = fps
        self.quality = quality
        self.overlay = overlay
        self._pool = pool
        self._record = ch.camera_info_record(host.vehicle.cameras[camera])
        self._task: asyncio.Task | None = None
        self.frames = Broadcast[JpegFrame](on_first=self._start, on_last=self._stop)
        self.encoded = 0
        self.cpu_s = 0.0
        self.age_ms: list[float] = []  # capture → encoded, the last 300
        self.arrival_ms: list[float] = []  # capture → the frame reached this process
        self.started_wall = time.monotonic()

    @property
    def viewers(self) -> int:
        return self.frames.subscriber_count

    def _start(self) -> None:
        if self._task is None or self._task.done():
            try:
                self._task = self.host.spawn(self._produce(), f"console-video-{self.camera}")
            except RuntimeError as exc:  # the run has not started or has ended: no video
                log.info("console video of %s not started: %s", self.camera, exc)

    def _stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            self._task = None

    async def _source(self, raw):
        """With overlays, the frame as the step's pipelines processed it (waiting the few
        milliseconds detection takes, at most a frame period), so that the detections drawn
        are those in that very image; bare, the frame as it came."""
        if not self.overlay:
            return raw
        rate = self._record.get("rate_hz") or 30.0
        processed = await self.host.processed_frame(self.camera, raw.seq, 1.0 / rate)
        return processed.frame if processed is not None else raw

    async def _produce(self) -> None:
        loop = asyncio.get_running_loop()
        sampler = FrameSampler(self.fps, self._record.get("rate_hz") or 30.0)
        failures = 0
        try:
            async with contextlib.aclosing(self.host.vehicle.frames(self.camera)) as frames:
                async for raw in frames:
                    if not sampler.take(time.monotonic()) or not self.host.take_frame(self.camera):
                        continue
                    arrival = (self.host.clock.now() - raw.time_s) * 1e3
                    self.arrival_ms = [*self.arrival_ms[-299:], arrival]
                    try:
                        await self._encode(loop, raw)
                    except Exception as exc:  # the console never takes the flight down
                        failures += 1
                        if failures == 1 or failures % 100 == 0:
                            log.warning("console video of %s: frame not drawn (%d so far): "
                                        "%s: %s", self.camera, failures, type(exc).__name__,
                                        exc)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # the camera's stream ended or failed
            log.warning("console video of %s stopped: %s: %s", self.camera,
                        type(exc).__name__, exc)

    async def _encode(self, loop, raw) -> None:
        frame = await self._source(raw)
        records = self.host.overlay_records(self.camera, frame)
        records["time_s"] = frame.time_s
        records["manual"] = self.host.manual
        jpeg, cpu = await loop.run_in_executor(self._pool, _draw_and_encode, frame.image,
                                               self._record, records, self.quality,
                                               self.overlay)
        self.encoded += 1
        self.cpu_s += cpu
        age = (self.host.clock.now() - frame.time_s) * 1e3
        self.age_ms = [*self.age_ms[-299:], age]
        self.frames.publish(JpegFrame(frame.seq, frame.time_s, jpeg, age))

    async def stream(self, fps: float | None) -> AsyncIterator[bytes]:
        """multipart/x-mixed-replace parts, at most ``fps`` a second (wall clock)."""
        period = 1.0 / min(fps or self.fps, self.fps)
        next_s = 0.0
        async with contextlib.aclosing(self.frames.subscribe()) as frames:
            async for item in frames:
                now = time.monotonic()
                if now < next_s - 0.25 * period:
                    continue
                next_s = max(next_s + period, now)
                head = (f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\n"
                        f"Content-Length: {len(item.jpeg)}\r\nX-Frame-Seq: {item.seq}\r\n"
                        f"X-Frame-Time: {item.time_s:.6f}\r\n"
                        f"X-Frame-Age-Ms: {item.age_ms:.1f}\r\n\r\n").encode()
                yield head + item.jpeg + b"\r\n"

    def stats(self) -> dict:
        wall = max(time.monotonic() - self.started_wall, 1e-9)
        ages = sorted(self.age_ms)
        arrivals = sorted(self.arrival_ms)
        return {"viewers": self.viewers, "frames_encoded": self.encoded,
                "encode_cpu_s": round(self.cpu_s, 3),
                "encode_ms_mean": round(1e3 * self.cpu_s / self.encoded, 2)
                if self.encoded else None,
                "encode_core_share": round(self.cpu_s / wall, 4),
                "capture_to_encoded_ms_p50": round(ages[len(ages) // 2], 1) if ages else None,
                "capture_to_encoded_ms_p95": round(ages[int(0.95 * (len(ages) - 1))], 1)
                if ages else None,
                "capture_to_arrival_ms_p50": round(arrivals[len(arrivals) // 2], 1)
                if arrivals else None}


class Console:
    """The console's server side, for one flight (see the module's docstring)."""

    def __init__(self, host: ConsolePort) -> None:
        self.host = host
        self.settings = host.config.console
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="console-video",
                                        initializer=lower_this_thread)
        self._feeds: dict[tuple[str, bool], CameraFeed] = {}

    def feed(self, camera: str, overlay: bool = True) -> CameraFeed:
        key = (camera, overlay)
        if key not in self._feeds:
            self._feeds[key] = CameraFeed(self.host, camera, self.settings.video_fps,
                                          self.settings.jpeg_quality, self._pool, overlay)
        return self._feeds[key]

    def stats(self) -> dict:
        return {"video": {f"{camera}{'' if overlay else ' (bare)'}": feed.stats()
                          for (camera, overlay), feed in self._feeds.items()}}

    def hello(self) -> dict:
        from autopilot.goals import goal_kinds

        keys = self.settings.keys.model_dump()
        about = self.host.console_about()
        return {"type": "hello", "keys": keys, "axes": list(AXES), "actions": list(ACTIONS),
                "cameras": list(self.host.vehicle.cameras),
                "video_fps": self.settings.video_fps,
                "key_renew_s": min(0.1, self.settings.key_timeout_s / 3),
                "goal_kinds": list(goal_kinds()) if about["takes_goals"] else [], **about}

    def state(self) -> dict:
        rt = self.host
        board = rt.values.snapshot()
        now = time.monotonic()
        return {"type": "state", "status": rt.api_status(),
                # name → [value, unit, seconds since published]
                "values": {name: [v.value, v.unit, round(now - v.time_s, 2)]
                           for name, v in sorted(board.items())},
                "held": sorted(rt.held_keys.held(rt.key_clock())),
                "map": rt.map_snapshot()}

    def handle(self, message: object, source: object = None) -> dict | None:
        """A message from the page → the answer to send back (None: none)."""
        if not isinstance(message, dict) or not isinstance(message.get("type"), str):
            return {"type": "error", "error": "expected a JSON object with a \"type\""}
        kind = message["type"]
        if kind == "keys":
            held = message.get("held", [])
            if not isinstance(held, list) or not all(isinstance(a, str) for a in held) \
                    or len(held) > len(AXES):
                return {"type": "error", "error": f"keys: \"held\" must be a list of axes "
                        f"({', '.join(AXES)})"}
            self.host.console_keys(held, source)
            return None
        if kind == "action":
            action = message.get("action")
            try:
                text = self.host.console_action(str(action),
                                                   confirm=message.get("confirm") is True)
            except ValueError as exc:
                return {"type": "answer", "action": action, "ok": False, "text": str(exc)}
            return {"type": "answer", "action": action, "ok": True, "text": text}
        return {"type": "error", "error": f"unknown message type {kind!r} (keys, action)"}

    async def serve_socket(self, ws) -> None:
        """One page's socket: push hello, state, path and events; take keys and actions.
        When it closes (the tab, the network), its held keys are let go at once."""
        rt = self.host
        source = object()  # this page: its keys are its own
        history = list(rt.events.recent)  # (taken before subscribing: none twice)
        events = rt.events.subscribe(name="console-socket", length=512)
        lock = asyncio.Lock()

        async def send(obj: dict) -> None:
            async with lock:
                await ws.send_text(json.dumps(ch.clean(obj), default=str))

        async def push_state() -> None:
            period = 1.0 / self.settings.state_rate_hz
            path_id = -1
            while True:
                await send(self.state())
                if rt.planned_path[0] != path_id:
                    path_id, points = rt.planned_path
                    await send({"type": "path", "id": path_id, "points_ne_m": points})
                await asyncio.sleep(period)  # (wall clock: it is for people)

        async def push_events() -> None:
            async for event in events:
                await send({"type": "event", **event.as_dict()})

        async def receive() -> None:
            while True:
                text = await ws.receive_text()
                if len(text) > 4096:
                    await send({"type": "error", "error": "message too long"})
                    continue
                try:
                    message = json.loads(text)
                except json.JSONDecodeError as exc:
                    await send({"type": "error", "error": f"not JSON: {exc}"})
                    continue
                answer = self.handle(message, source)
                if answer is not None:
                    await send(answer)

        tasks: list[asyncio.Future] = []
        try:
            await send(self.hello())
            for event in history:  # what happened before the page opened
                await send({"type": "event", **event.as_dict()})
            tasks = [asyncio.ensure_future(c) for c in (push_state(), push_events(), receive())]
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        except Exception:  # the page went away, or the server is closing
            pass
        finally:
            rt.console_release(source)  # a dropped socket lets go of its keys: hover
            events.close()
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    def close(self) -> None:
        """The run is over: each camera's producer stops and its viewers' streams end (their
        responses finish, so the server closes them cleanly instead of cancelling them)."""
        for feed in self._feeds.values():
            feed._stop()
            feed.frames.close()
        self._pool.shutdown(wait=False, cancel_futures=True)
