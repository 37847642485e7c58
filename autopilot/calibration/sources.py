"""Where the frames come from: an image folder, a video file, or a live stream."""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from autopilot.calibration.common import (
    IMAGE_SUFFIXES,
    LIVE_DEFAULT_DURATION_S,
    LIVE_DEFAULT_FRAMES,
    Log,
    SourceKind,
    no_log,
)
from autopilot.config import InputError


@dataclass(frozen=True, slots=True, eq=False)
class SourceFrame:
    name: str
    image: np.ndarray  # BGR or grey, uint8


class FrameSource:
    """Frames from an image folder (its images in name order), a video file, or a live
    stream: ``udp://`` / ``rtp://`` is RTP H.264 (:class:`drivers.video.VideoSource`, as PX4
    cameras and ``autopilot sim`` send it), anything else (``rtsp://``, ``http://``,
    ``/dev/video0``, a device number) goes to ``cv2.VideoCapture``.

    ``max_frames`` and ``duration_s`` bound what is read (a live source defaults to
    :data:`LIVE_DEFAULT_FRAMES` and :data:`LIVE_DEFAULT_DURATION_S`); ``every`` keeps every
    n-th frame. Ctrl-C while a live source is read ends the reading and
    :func:`calibrate_frames` uses the frames so far. :class:`InputError` for a source that
    does not exist or does not open."""

    def __init__(self, source: str, *, max_frames: int | None = None,
                 duration_s: float | None = None, every: int = 1,
                 open_timeout_s: float = 10.0, log: Log = no_log) -> None:
        if every < 1:
            raise InputError(f"--every {every}: must be at least 1")
        if max_frames is not None and max_frames < 1:
            raise InputError(f"--frames {max_frames}: must be at least 1")
        if duration_s is not None and not duration_s > 0.0:
            raise InputError(f"--duration-s {duration_s}: must be positive")
        self.source = source
        self.kind: SourceKind = source_kind(source)
        live = self.kind == "live"
        self.max_frames = max_frames if max_frames is not None or not live \
            else LIVE_DEFAULT_FRAMES
        self.duration_s = duration_s if duration_s is not None or not live \
            else LIVE_DEFAULT_DURATION_S
        self.every = every
        self.open_timeout_s = open_timeout_s
        self.log = log
        #: Files of a folder that could not be read as images.
        self.skipped: list[str] = []
        self._files: list[Path] = []
        if self.kind == "folder":
            folder = Path(source)
            self._files = sorted(p for p in folder.iterdir()
                                 if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
            if not self._files:
                raise InputError(f"{source}: no images in this folder (expected "
                                 f"{', '.join(IMAGE_SUFFIXES)} files)")

    @property
    def live(self) -> bool:
        """A live stream: Ctrl-C ends the reading, and the frames so far are used."""
        return self.kind == "live"

    def describe(self) -> str:
        if self.kind == "folder":
            return f"{self.source} (folder, {len(self._files)} images)"
        limits = [f"{self.max_frames} frames" if self.max_frames else None,
                  f"{self.duration_s:g} s" if self.duration_s else None]
        bound = " or ".join(x for x in limits if x)
        return f"{self.source} ({self.kind}{', up to ' + bound if bound else ''})"

    def __iter__(self) -> Iterator[SourceFrame]:
        if self.kind == "folder":
            yield from self._folder()
        elif self.kind == "live" and is_rtp(self.source):
            yield from self._limited(self._rtp())
        else:
            yield from self._limited(self._capture())

    def _folder(self) -> Iterator[SourceFrame]:
        files = self._files[::self.every][:self.max_frames]
        read = 0
        for path in files:
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if image is None or image.dtype != np.uint8:
                self.skipped.append(path.name)
                self.log(f"{path}: not an 8-bit image OpenCV reads; skipped")
                continue
            read += 1
            yield SourceFrame(path.name, image)
        if read == 0:
            raise InputError(f"{self.source}: none of its {len(files)} image files could be "
                             "read (8-bit PNG, JPEG, ... expected)")

    def _limited(self, frames: Iterator[np.ndarray]) -> Iterator[SourceFrame]:
        started = time.monotonic()
        kept = 0
        try:
            for n, image in enumerate(frames):
                if self.duration_s is not None and time.monotonic() - started > self.duration_s:
                    break
                if n % self.every:
                    continue
                yield SourceFrame(f"frame {n}", image)
                kept += 1
                if self.max_frames is not None and kept >= self.max_frames:
                    break
        finally:
            close = getattr(frames, "close", None)
            if close is not None:
                close()

    def _capture(self) -> Iterator[np.ndarray]:
        target = int(self.source) if self.source.isdigit() else self.source
        capture = cv2.VideoCapture(target)
        try:
            if not capture.isOpened():
                raise InputError(f"{self.source}: OpenCV cannot open this as a video "
                                 f"{'stream' if self.kind == 'live' else 'file'}")
            got = False
            while True:
                ok, image = capture.read()
                if not ok:
                    break
                got = True
                yield image
            if not got:
                raise InputError(f"{self.source}: opened, but no frame could be read")
        finally:
            capture.release()

    def _rtp(self) -> Iterator[np.ndarray]:
        """RTP H.264 received and decoded by the project's video receiver (on an event loop
        of its own, on a thread); the newest frame is handed over, older ones dropped while
        the caller is busy detecting."""
        import asyncio

        from drivers.base import CameraInfo
        from drivers.camera_model import pinhole
        from drivers.video import VideoSource, check_video_url

        try:
            check_video_url(self.source)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        # the receiver wants a camera to stamp frames for: the intrinsics are what we are
        # about to measure, so any will do
        info = CameraInfo("calibrate", pinhole(640, 480, 90.0), np.eye(3), np.zeros(3), 30.0)
        newest: queue.Queue[np.ndarray] = queue.Queue(maxsize=1)
        stop = threading.Event()
        failure: list[BaseException] = []

        async def pump() -> None:
            video = VideoSource(self.source, info)
            try:
                async with contextlib.aclosing(video.frames()) as frames:
                    pending = asyncio.ensure_future(anext(frames))
                    while not stop.is_set():
                        done, _ = await asyncio.wait({pending}, timeout=0.2)
                        if not done:
                            continue
                        image = pending.result()
                        pending = asyncio.ensure_future(anext(frames))
                        with contextlib.suppress(queue.Empty):
                            newest.get_nowait()
                        newest.put_nowait(image.image)
                    pending.cancel()
            finally:
                await video.close()

        def run() -> None:
            try:
                asyncio.run(pump())
            except BaseException as exc:  # handed to the reading thread
                failure.append(exc)

        thread = threading.Thread(target=run, name="calibrate-video", daemon=True)
        thread.start()
        try:
            got = 0
            while True:
                try:
                    image = newest.get(timeout=self.open_timeout_s if got == 0 else 5.0)
                except queue.Empty:
                    if failure:
                        raise InputError(f"{self.source}: {failure[0]}") from None
                    if got == 0:
                        raise InputError(
                            f"{self.source}: no frame within {self.open_timeout_s:g} s: is "
                            "the camera streaming RTP H.264 to this address and port?") from None
                    self.log(f"{self.source}: no frame for 5 s; the stream stopped")
                    return
                got += 1
                yield image
        finally:
            stop.set()
            thread.join(5.0)


def is_rtp(source: str) -> bool:
    return source.split("://", 1)[0].lower() in ("udp", "rtp") and "://" in source


def source_kind(source: str) -> SourceKind:
    path = Path(source)
    if "://" in source or source.isdigit() or source.startswith("/dev/"):
        return "live"
    if path.is_dir():
        return "folder"
    if path.is_file():
        return "video"
    raise InputError(f"{source}: no such file or folder (SOURCE is an image folder, a video "
                     "file, or a live video URL such as udp://127.0.0.1:5600)")
