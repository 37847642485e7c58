"""The AR.Drone 2.0 driver's cameras as frame streams (:class:`VideoFeed`), and the drone's
video stream as frames (:class:`PaveFrames`).

The drone streams one camera at a time: while a camera has subscribers the feed reads the
stream, and a subscription to the other camera selects it (``video:video_channel``), the
newest subscription winning while both have subscribers. A stream that fails or ends is read
afresh after :data:`VIDEO_RETRY_S`.

:class:`PaveFrames` reads TCP 5555 (:class:`~drivers.ardrone.pave.PaveReader`), decodes in a
thread of its own (:class:`~drivers.ardrone.video.PaveDecoder`), and stamps each frame with
its PaVE capture time mapped onto our clock (:class:`~drivers.ardrone.cameras.VideoClock`).
"""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections.abc import AsyncIterator, Callable, Mapping
from concurrent.futures import ThreadPoolExecutor

from drivers.ardrone import pave
from drivers.ardrone.cameras import VideoClock, camera_of_frame
from drivers.ardrone.video import PaveDecoder
from drivers.base import CameraInfo, Frame, VehicleError
from drivers.clock import Clock
from drivers.slots import Broadcast

log = logging.getLogger(__name__)

#: a video connection that failed or ended is made again after this long
VIDEO_RETRY_S = 1.0

#: the frames of the stream the drone sends now, until it ends
FrameSource = Callable[[], AsyncIterator[Frame]]


class VideoFeed:
    """The cameras' streams. ``select(camera)`` switches the drone's stream to a camera;
    ``source()`` reads the stream; ``on_close()`` releases what it holds."""

    def __init__(self, cameras: Mapping[str, CameraInfo], clock: Clock,
                 select: Callable[[str], None], source: FrameSource, host: str = "",
                 on_close: Callable[[], None] | None = None) -> None:
        self._clock = clock
        self._on_close = on_close
        self._select_channel = select
        self._source = source
        self._host = host
        self._frames: dict[str, Broadcast[Frame]] = {
            name: Broadcast(on_first=lambda n=name: self._watch(n, True),
                            on_last=lambda n=name: self._watch(n, False))
            for name in cameras}
        self._watched: list[str] = []  # cameras with subscribers, the newest last
        #: what video:video_channel was last set to (None: not yet; whatever the drone has)
        self.channel_camera: str | None = None
        self._task: asyncio.Task | None = None
        self._closed = False
        self.frames_published = 0

    def subscribe(self, camera: str) -> AsyncIterator[Frame]:
        if camera not in self._frames:
            raise ValueError(f"no camera {camera!r}; this vehicle has {sorted(self._frames)}")
        return self._frames[camera].subscribe()

    def close(self) -> None:
        self._closed = True
        if self._task is not None:
            self._task.cancel()
            self._task = None
        for broadcast in self._frames.values():
            broadcast.close()
        if self._on_close is not None:
            self._on_close()

    def _watch(self, camera: str, on: bool) -> None:
        """A camera's first subscriber came (``on``) or its last left."""
        if camera in self._watched:
            self._watched.remove(camera)
        if on:
            self._watched.append(camera)
        if self._watched:
            newest = self._watched[-1]
            if newest != self.channel_camera:
                self.channel_camera = newest
                self._select_channel(newest)
            if self._task is None and not self._closed:
                self._task = asyncio.get_running_loop().create_task(self._run(),
                                                                    name="ardrone-video")
        elif self._task is not None:
            self._task.cancel()
            self._task = None

    async def _run(self) -> None:
        while True:
            try:
                async for frame in self._source():
                    broadcast = self._frames.get(frame.camera.name)
                    if broadcast is not None:
                        self.frames_published += 1
                        broadcast.publish(frame)
            except VehicleError:
                return
            except OSError as exc:
                log.warning("AR.Drone at %s: video: %s", self._host, exc)
            except Exception:  # (a decoder's surprise: the stream is read afresh)
                log.exception("AR.Drone at %s: video", self._host)
            await self._clock.sleep(VIDEO_RETRY_S)


class PaveFrames:
    """The drone's video stream over its link, as frames: ``channel()`` is the camera it was
    last switched to (frames are told apart by their size, that camera if both match)."""

    def __init__(self, link, clock: Clock, cameras: Mapping[str, CameraInfo],
                 channel: Callable[[], str | None], latency_s: float = 0.05) -> None:
        self._link = link
        self._clock = clock
        self._cameras = cameras
        self._channel = channel
        #: the drone's clock onto ours, from the frames' PaVE timestamps
        self.video_clock = VideoClock(latency_s)
        self._seq = itertools.count()
        self._executor: ThreadPoolExecutor | None = None

    async def __call__(self) -> AsyncIterator[Frame]:
        """One connection to the video port, read until it ends."""
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ardrone-video")
        reader, writer = await self._link.open_video()
        packets, decoder = pave.PaveReader(), PaveDecoder()
        try:
            while data := await reader.read(1 << 16):
                arrival = self._clock.now()
                for header, payload in packets.feed(data):
                    decoded = await self._clock.run_blocking(decoder.decode, header, payload,
                                                             executor=self._executor)
                    for frame in decoded:
                        height_px, width_px = frame.image.shape[:2]
                        name = camera_of_frame(width_px, height_px, self._cameras,
                                               self._channel() or "front")
                        image = frame.image
                        image.flags.writeable = False
                        yield Frame(self._cameras[name],
                                    self.video_clock.map(frame.time_s, arrival),
                                    next(self._seq), image)
        finally:
            writer.close()

    def close(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
