"""The console's video at the run's end: a viewer's MJPEG stream ends when the console closes
(its response finishes and the server closes the connection cleanly), rather than waiting for
frames that will never come until the server cancels it — which uvicorn logs as "Exception in
ASGI application" with a traceback on the operator's terminal."""

import asyncio
from types import SimpleNamespace

import numpy as np

from autopilot.config import load_config
from autopilot.console import Console
from drivers.base import CameraInfo, CameraIntrinsics


class _Runtime:
    def __init__(self) -> None:
        self.config = load_config()
        info = CameraInfo("front", CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0),
                          np.eye(3), np.zeros(3), 30.0)
        self.vehicle = SimpleNamespace(cameras={"front": info})
        self.spawned: list[asyncio.Task] = []

    def spawn(self, coro, name):
        coro.close()  # a camera that never delivers (the run is ending)

        async def idle():
            await asyncio.Event().wait()
        task = asyncio.get_running_loop().create_task(idle(), name=name)
        self.spawned.append(task)
        return task


def test_closing_the_console_ends_every_viewers_stream():
    async def main():
        runtime = _Runtime()
        console = Console(runtime)
        feed = console.feed("front")
        parts: list[bytes] = []

        async def viewer():
            async for part in feed.stream(15):
                parts.append(part)

        watching = asyncio.create_task(viewer())
        await asyncio.sleep(0.05)
        assert feed.viewers == 1
        assert runtime.spawned  # encoding while watched
        assert not runtime.spawned[0].done()
        console.close()
        await asyncio.wait_for(watching, 1.0)  # the stream ended by itself
        assert feed.viewers == 0
        await asyncio.sleep(0)
        assert runtime.spawned[0].cancelled()
        # a viewer arriving after the end gets an empty stream at once
        await asyncio.wait_for(viewer(), 1.0)
        assert parts == []

    asyncio.run(main())
