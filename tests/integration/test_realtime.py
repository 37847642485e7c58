"""The real-time clock: samples are stamped on the monotonic clock and arrive as they happen.

This checks wiring, not speed: bounds are loose so that a busy machine does not fail it."""

import contextlib
import itertools

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


def _slow_physics(monkeypatch, factor: float) -> None:
    """Make every batch of physics take ``factor`` times the time it simulates (a CPU that
    cannot keep up), whatever the machine's real speed."""
    import time

    from drivers.sim.simulator import Simulator

    original = Simulator.advance_to

    def slow(self, until_s):
        started, start_s = time.perf_counter(), self.time_s
        out = original(self, until_s)
        spare = factor * (self.time_s - start_s) - (time.perf_counter() - started)
        if spare > 0.0:
            time.sleep(spare)
        return out

    monkeypatch.setattr(Simulator, "advance_to", slow)


def test_a_slow_simulator_slows_its_world_and_says_so(sim_config, monkeypatch, caplog):
    """At a third of real time the simulated world slows as a whole: its samples arrive as
    fresh as at full speed (not ever older, as a clock running on would make them), the
    clock stays monotonic, and one warning names the real-time factor."""
    import logging

    _slow_physics(monkeypatch, 3.0)

    async def main():
        async with simulator(sim_config, lockstep=False) as drv:
            lags, reads = [], []
            async with contextlib.aclosing(drv.telemetry()) as stream:
                async for state in stream:
                    lags.append(drv.clock.now() - state.time_s)
                    reads.append(drv.clock.now())
                    if state.time_s > 2.5:
                        break
            async with contextlib.aclosing(drv.frames("front")) as stream:
                frame = await anext(stream)
                frame_lag = drv.clock.now() - frame.time_s
            return lags, reads, frame_lag, drv.slowest_pace_factor, drv.clock.held_back_s

    with caplog.at_level(logging.WARNING, logger="drivers.sim.driver"):
        lags, reads, frame_lag, factor, held_back = run(main())
    # 2.5 s simulated took ~7.5 s: unpaced, the last samples would arrive 5 s old
    assert held_back > 3.0
    assert factor < 0.6
    assert sorted(lags)[len(lags) // 2] < 0.25
    assert max(lags[len(lags) // 2:]) < 1.0
    assert all(b >= a for a, b in itertools.pairwise(reads))
    assert 0.0 <= frame_lag < 1.0
    slow = [r.getMessage() for r in caplog.records if "× real time" in r.getMessage()]
    assert len(slow) == 1
    assert slow[0].startswith("simulator at 0.")


def test_a_stand_alone_vehicle_sheds_rendering_when_behind(sim_config, monkeypatch, caplog):
    """``autopilot sim``'s setting: behind real time, frames are skipped (physics and telemetry
    first), and the warning repeats while it lasts."""
    import logging

    _slow_physics(monkeypatch, 2.0)

    async def main():
        async with simulator(sim_config, lockstep=False, warn_every_s=0.5,
                             shed_rendering=True) as drv:
            received = 0
            async with contextlib.aclosing(drv.frames("front")) as frames:
                async for frame in frames:
                    received += 1
                    if frame.time_s > 2.5:
                        break
            cam = drv.simulator.cameras["front"]
            return received, cam.shed, cam.rendered

    with caplog.at_level(logging.WARNING, logger="drivers.sim.driver"):
        received, shed, rendered = run(main())
    # half the frames were not rendered; the video went on with the other half
    assert shed > 10
    assert rendered >= shed
    assert received > 10
    slow = [r.getMessage() for r in caplog.records if "× real time" in r.getMessage()]
    assert len(slow) >= 2
    assert "lags the wall clock" in slow[0]
    assert "frames not rendered" in slow[0]
