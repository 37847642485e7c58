"""The event loop's watchdog on the wall clock: it measures the loop's lag and reports a stall
while it lasts; in a real-time flight a stalled loop ends in the fallback. (The lockstep
failsafes are in test_failsafes.py.)"""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.watchdog import LoopWatchdog

from .simtools import ended_down, fly_short

pytestmark = pytest.mark.serial  # the wall clock: a stall measured, a real-time flight

_fly = fly_short


# -- the event loop's watchdog ---------------------------------------------------------------

def test_watchdog_measures_lag_and_reports_a_stall_while_it_lasts(caplog):
    stalls = []

    async def main():
        dog = LoopWatchdog(0.2, stalls.append, period_s=0.02)
        task = asyncio.ensure_future(dog.run())
        await asyncio.sleep(0.2)
        time.sleep(0.6)  # noqa: ASYNC251 - the loop is stuck here (on purpose)
        await asyncio.sleep(0.1)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        return dog

    with caplog.at_level(logging.WARNING, logger="autopilot.watchdog"):
        dog = asyncio.run(main())
    assert len(stalls) == 1
    assert stalls[0] == pytest.approx(0.6, abs=0.15)
    during = [r for r in caplog.records if "has not answered" in r.getMessage()]
    assert during  # logged by the thread while the loop was stuck, with where it was
    assert "time.sleep(0.6)" in during[0].getMessage()
    assert dog.lag_percentile_ms(50) < 50.0
    assert dog.lag_percentile_ms(100) > 400.0


@pytest.mark.long
def test_a_stalled_event_loop_in_real_time_ends_in_the_fallback(monkeypatch, tmp_path):
    """Real time: the loop blocks for 1.5 s while following; setpoints stop, the vehicle's
    offboard failsafe holds it; back, the autopilot does not resume the step: fallback, land."""
    from autopilot.runtime.control import ControlLoop

    original = ControlLoop.next_tick
    stalled = []

    async def stalling(self, period):
        if self.flight.cursor.step == "follow_ball" and self.flight.clock.now() > 10.0 and \
                not stalled:
            stalled.append(True)
            time.sleep(1.5)  # noqa: ASYNC251 - a blocking call on the event loop (on purpose)
        return await original(self, period)

    monkeypatch.setattr(ControlLoop, "next_tick", stalling)
    summary, orphans = _fly([], tmp_path, realtime=True)
    # back from the stall the step does not resume: the stall's own failsafe stops it (the
    # telemetry queued meanwhile arrives at once, so the vehicle is not silent past its
    # telemetry_grace_s; the silence guard holds the step at most)
    assert summary["status"] in ("failed", "aborted")
    assert "event loop stalled" in summary["reason"] or "telemetry lost" in summary["reason"]
    assert orphans == []
    log = read_log(tmp_path / "flight.mcap")
    texts = [e["text"] for e in log[ch.MISSION_EVENTS]]
    stalled = next(i for i, t in enumerate(texts) if t.startswith("event loop stalled for 1."))
    assert "fallback safe_stop started" in texts[stalled:]
    modes = [s["mode"] for s in log[ch.VEHICLE_STATE] if s["time_s"] > 10.0]
    assert "hold" in modes  # the vehicle's own offboard-loss failsafe
    ended_down(log)
