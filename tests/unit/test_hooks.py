"""Event hooks: names as seed 000's, subscribers by kind or hook, and hooks that cannot hold up
the control loop (a slow or failing one is dropped and logged)."""

from __future__ import annotations

import asyncio
import logging
import threading
import time

import pytest

from autopilot.hooks import Event, EventHub

pytestmark = pytest.mark.serial  # the event loop's lag on the wall clock


def test_hook_names_follow_seed_000():
    assert Event("status", "hover", 1.0).hook == "on_status_hover"
    assert Event("status", "follow ball in progress", 1.0).hook == \
        "on_status_follow_ball_in_progress"
    assert Event("command", "land", 1.0, phase="before").hook == "before_cmd_land"
    assert Event("command", "start_offboard", 1.0, phase="after").hook == \
        "after_cmd_start_offboard"
    assert Event("mode", "offboard", 1.0).hook == "on_mode_offboard"
    assert Event("armed", "disarmed", 1.0).hook == "on_disarmed"
    assert Event("step_started", "orbit", 1.0).hook == "on_step_started"
    with pytest.raises(ValueError, match="unknown event kind"):
        Event("nonsense", "x", 0.0)
    event = Event("command", "takeoff", 2.0, phase="before", data={"altitude_m": 3.0})
    with pytest.raises(TypeError):
        event.data["altitude_m"] = 5.0  # read-only
    assert event.as_dict()["hook"] == "before_cmd_takeoff"


def test_subscribers_get_what_they_asked_for_in_order():
    async def main():
        hub = EventHub()
        everything = hub.subscribe()
        status = hub.subscribe("status")
        land = hub.subscribe({"before_cmd_land", "mode"})
        hub.emit(Event("status", "hover", 1.0))
        hub.emit(Event("command", "land", 2.0, phase="before"))
        hub.emit(Event("command", "land", 2.5, phase="after"))
        hub.emit(Event("mode", "land", 2.6))
        hub.close()
        return ([e.hook async for e in everything], [e.hook async for e in status],
                [e.hook async for e in land])

    every, status, land = asyncio.run(main())
    assert every == ["on_status_hover", "before_cmd_land", "after_cmd_land", "on_mode_land"]
    assert status == ["on_status_hover"]
    assert land == ["before_cmd_land", "on_mode_land"]
    with pytest.raises(ValueError, match="not an event kind or hook"):
        EventHub().subscribe("bogus")


def test_a_subscriber_that_falls_behind_is_dropped_not_waited_for(caplog):
    async def main():
        hub = EventHub()
        slow = hub.subscribe(length=4, name="slow-reader")
        started = time.perf_counter()
        for i in range(100):  # nobody reads: emit never waits
            hub.emit(Event("status", f"s{i}", float(i)))
        elapsed = time.perf_counter() - started
        got = [e.name async for e in slow]
        return elapsed, got, slow.dropped, hub.dropped

    with caplog.at_level(logging.WARNING):
        elapsed, got, dropped, hub_dropped = asyncio.run(main())
    assert dropped == "4 events behind"
    assert got == []  # dropped: the iteration ends
    assert hub_dropped == [("slow-reader", "4 events behind")]
    assert "event hook slow-reader dropped" in caplog.text
    assert elapsed < 1.0


def test_callbacks_run_off_the_loop_and_slow_or_failing_ones_are_dropped(caplog):
    seen: list[str] = []
    threads: list[str] = []
    release = threading.Event()

    def quick(event):
        threads.append(threading.current_thread().name)
        seen.append(event.hook)

    def blocking(event):  # blocks its (hooks) thread, never the loop
        release.wait(5.0)

    async def slow_async(event):
        await asyncio.sleep(10.0)

    def broken(event):
        raise RuntimeError("bug in a hook")

    async def main():
        hub = EventHub(callback_timeout_s=0.2)
        async with asyncio.TaskGroup() as group:
            hub.on("status", quick)
            subs = [hub.on("mode", blocking), hub.on("mode", slow_async),
                    hub.on("armed", broken)]
            runners = hub.tasks(group)
            loop_lag = []
            for i in range(5):
                t0 = time.perf_counter()
                hub.emit(Event("status", f"s{i}", float(i)))
                hub.emit(Event("mode", "hold", float(i)))
                hub.emit(Event("armed", "armed", float(i)))
                await asyncio.sleep(0.1)
                loop_lag.append(time.perf_counter() - t0 - 0.1)
            release.set()
            await asyncio.sleep(0.2)
            dropped = [s.dropped for s in subs]
            hub.close()
            await asyncio.wait_for(asyncio.gather(*runners, return_exceptions=True), 5.0)
        return loop_lag, dropped

    with caplog.at_level(logging.WARNING):
        loop_lag, dropped = asyncio.run(main())
    assert seen == [f"on_status_s{i}" for i in range(5)]
    assert all(name.startswith("hooks") for name in threads)
    assert max(loop_lag) < 0.1  # the loop kept its pace while hooks blocked
    assert dropped[0] == "took longer than 0.2 s"
    assert dropped[1] == "took longer than 0.2 s"
    assert dropped[2] == "raised RuntimeError: bug in a hook"
    assert "bug in a hook" in caplog.text
