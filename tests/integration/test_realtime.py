"""The real-time clock: samples are stamped on the monotonic clock and arrive as they happen.

This checks wiring, not speed: bounds are loose so that a busy machine does not fail it."""

import contextlib

from .simtools import run, simulator


def test_realtime_telemetry_and_frames(sim_config):
    async def main():
        async with simulator(sim_config, lockstep=False) as drv:
            assert not drv.clock.lockstep
            lags = []
            async with contextlib.aclosing(drv.telemetry()) as stream:
                async for state in stream:
                    lags.append(drv.clock.now() - state.time_s)
                    if state.time_s > 0.5:
                        break
            async with contextlib.aclosing(drv.frames("front")) as stream:
                frame = await anext(stream)
            return lags, frame, drv.clock.now()

    lags, frame, now = run(main())
    assert len(lags) >= 10
    assert all(lag >= 0.0 for lag in lags)
    assert sorted(lags)[len(lags) // 2] < 0.25  # median: arrives close to when it happened
    assert 0.0 <= now - frame.time_s < 1.0
