"""Camera frames for the flight log: which ones (a rate per camera), JPEG-encoded off the loop.

:class:`FrameLogger` subscribes to each logged camera itself, for the whole run (it does not
depend on which cameras the mission's steps are using), samples frames at the configured rate,
and encodes them in its own executor. It never makes the rest of the pipeline wait: when its
buffer is full a frame is dropped and counted.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import deque
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from autopilot.flightlog.log import FlightLog
from drivers.base import Frame, Vehicle
from drivers.rate import RateSampler
from drivers.threads import lower_this_thread

FRAME_LOG_BUFFER = 32  # frames waiting for JPEG encoding; more are dropped (and counted)
FRAME_LOG_PIPELINE = 3  # frames being encoded at once (each within this many frame periods)


class FrameSampler(RateSampler):
    """Which frames of a camera go to the log: ``rate_hz`` per second on average, evenly
    spread; every frame when the rate is at or above the camera's."""

    def __init__(self, rate_hz: float, camera_rate_hz: float) -> None:
        super().__init__(rate_hz, camera_rate_hz)


def encode_jpeg(image_bgr: np.ndarray, quality: int) -> bytes:
    """JPEG without chroma subsampling (4:4:4): colour detection lives on the chroma, and
    halving its resolution moves a ball's edge by a few tenths of a pixel."""
    ok, buffer = cv2.imencode(".jpg", image_bgr, [
        cv2.IMWRITE_JPEG_QUALITY, quality,
        cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buffer.tobytes()


class FrameLogger:
    """Logs sampled frames of ``rates`` (camera name → frames per second) to ``log``."""

    def __init__(self, vehicle: Vehicle, log: FlightLog, rates: Mapping[str, float],
                 quality: int) -> None:
        self.vehicle = vehicle
        self.log = log
        self.clock = vehicle.clock
        self.quality = quality
        cams = vehicle.cameras
        self.samplers = {} if log.path is None else {
            name: FrameSampler(rate, cams[name].rate_hz)
            for name, rate in rates.items() if rate > 0 and name in cams}
        self.dropped = 0
        self._to_log: asyncio.Queue[Frame] = asyncio.Queue(maxsize=FRAME_LOG_BUFFER)
        self._pool: ThreadPoolExecutor | None = None
        self._encoding: deque[tuple[Frame, asyncio.Future[bytes]]] = deque()

    @property
    def active(self) -> bool:
        return bool(self.samplers)

    def tasks(self, group: asyncio.TaskGroup) -> list[asyncio.Task]:
        """Start the logger's tasks in ``group`` (the caller cancels them at the end of the run,
        then calls :meth:`close`)."""
        if not self.samplers:
            return []
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="frame-log",
                                        initializer=lower_this_thread)
        return [group.create_task(self._encode(), name="frame-log"),
                *(group.create_task(self._camera(name), name=f"frame-log-{name}")
                  for name in self.samplers)]

    def close(self) -> None:
        """Write the frames still waiting (the last second of a flight belongs in its video),
        then release the encoder."""
        waiting = [frame for frame, _ in self._encoding]
        self._encoding.clear()
        while not self._to_log.empty():
            waiting.append(self._to_log.get_nowait())
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        for frame in waiting:
            with contextlib.suppress(Exception):  # the run's outcome matters more than a frame
                self.log.write_image(frame.camera.name, frame.time_s,
                                     frame.jpeg or encode_jpeg(frame.image, self.quality))

    async def _camera(self, name: str) -> None:
        sampler = self.samplers[name]
        async with contextlib.aclosing(self.vehicle.frames(name)) as frames:
            async for frame in frames:
                if not sampler.take(frame.time_s):
                    continue
                try:
                    self._to_log.put_nowait(frame)
                except asyncio.QueueFull:
                    self.dropped += 1

    async def _encode(self) -> None:
        """Encode frames (JPEG, off the loop) and write them in order.

        Up to ``FRAME_LOG_PIPELINE`` frames are in hand at once, each modelled (on the lockstep
        clock) as encoded within that many frame periods: the encoder uses the CPU the rest
        of the pipeline leaves idle instead of the simulator stopping for it every frame."""
        pending = self._encoding
        try:
            while True:
                frame = await self._to_log.get()
                if frame.jpeg is not None:  # the codec's own bytes, as the detectors saw them
                    job: asyncio.Future[bytes] = asyncio.get_running_loop().create_future()
                    job.set_result(frame.jpeg)
                else:
                    job = asyncio.ensure_future(self.clock.run_blocking(
                        encode_jpeg, frame.image, self.quality, executor=self._pool,
                        budget_s=FRAME_LOG_PIPELINE / frame.camera.rate_hz))
                pending.append((frame, job))
                while pending and (pending[0][1].done() or len(pending) >= FRAME_LOG_PIPELINE):
                    done, job = pending[0]
                    jpeg = await job
                    pending.popleft()
                    self.log.write_image(done.camera.name, done.time_s, jpeg)
        finally:
            for _, job in pending:
                job.cancel()
