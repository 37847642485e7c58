"""The real-time clock: samples are stamped on the monotonic clock and arrive as they happen.

This checks wiring, not speed: bounds are loose so that a busy machine does not fail it."""

import contextlib
import itertools
import sys

import pytest

from .simtools import run, simulator

pytestmark = pytest.mark.serial  # real-time flights


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
            pacer = drv.runner.pacer
            return lags, reads, frame_lag, pacer.slowest_pace_factor, drv.clock.held_back_s

    with caplog.at_level(logging.WARNING, logger="drivers.sim"):
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

    with caplog.at_level(logging.WARNING, logger="drivers.sim"):
        received, shed, rendered = run(main())
    # frames were skipped, not rendered, and the video went on with the others (how many of
    # each depends on what else the machine is doing: about half each when it is idle)
    assert shed > 10
    assert rendered > 10
    assert received > 10
    slow = [r.getMessage() for r in caplog.records if "× real time" in r.getMessage()]
    assert len(slow) >= 2
    assert "lags the wall clock" in slow[0]
    assert "frames not rendered" in slow[0]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice is Linux's")
@pytest.mark.parametrize("stand_alone", [False, True])
def test_the_simulator_yields_the_cpu_only_in_process(sim_config, stand_alone):
    """In process the simulator's threads (physics, telemetry, rendering) yield the CPU to the
    autopilot beside them, and the world slows as a whole; ``autopilot sim``'s vehicle runs at
    normal priority (lowered, it ran at 0.04× real time beside two busy processes, its clock
    lagging its client's, and a MAVSDK flight found no video)."""
    import os

    def niceness() -> int:
        return os.getpriority(os.PRIO_PROCESS, 0)  # Linux: the calling thread's

    async def main():
        async with simulator(sim_config, lockstep=False, background=not stand_alone) as drv:
            async with contextlib.aclosing(drv.frames("front")) as frames:
                await anext(frames)  # the render thread has drawn (and lowered itself)
            physics = drv.runner.executor.submit(niceness).result()
            render = drv.simulator.rig._executor().submit(niceness).result()
            return physics, render

    ours = niceness()
    physics, render = run(main())
    lowered = min(19, ours + 10)
    if stand_alone:
        assert (physics, render) == (ours, ours)
    else:
        assert physics == lowered
        assert render >= lowered


def test_shedding_physics_never_waits_for_a_frame_still_drawing(sim_config):
    """Behind real time, a frame not yet drawn when due is sent when it is drawn, and no frame
    is captured while its camera still draws the last: the physics steps on either way."""
    import threading

    from drivers.sim.simulator import Simulator

    sim = Simulator(sim_config)
    try:
        sim.set_camera_active("front", True)
        sim.captures.shed_rendering = True
        cam = sim.cameras["front"]
        release = threading.Event()
        # the render thread is busy (for 30 s at most: physics that waited would fail, not hang)
        sim.rig._executor().submit(release.wait, 30.0)
        outputs = sim.advance_to(0.5)  # 15 frames due: the first waits behind the busy thread
        assert sim.time_s >= 0.5
        assert not [o for o in outputs if o.kind == "frame"]
        assert any(o.kind == "telemetry" for o in outputs)
        assert cam.rendered == 1
        assert cam.shed >= 10
        release.set()
        sim.rig._executor().submit(lambda: None).result()  # (one thread: the frame is drawn)
        if cam.effects is not None:  # (and its camera model, on a thread of its own, applied)
            sim.rig._post_executor().submit(lambda: None).result()
        later = [o.payload for o in sim.advance_to(sim.time_s + 0.01) if o.kind == "frame"]
        (frame,) = later
        assert frame.time_s < 0.05  # captured when it was, delivered when drawn
    finally:
        sim.close()
