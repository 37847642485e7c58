import asyncio

import pytest

from drivers.clock import LockstepClock
from drivers.slots import Broadcast, LatestSlot, SlotClosed

pytestmark = pytest.mark.serial  # the wall clock


def test_latest_slot_keeps_newest_and_counts_drops():
    async def main():
        slot = LatestSlot()
        for i in range(5):
            slot.put(i)
        assert await slot.get() == 4
        assert slot.dropped == 4
        slot.close()
        with pytest.raises(SlotClosed):
            await slot.get()

    asyncio.run(main())


def test_buffered_slot_keeps_order():
    async def main():
        slot = LatestSlot(capacity=3)
        for i in range(5):
            slot.put(i)
        assert [await slot.get() for _ in range(3)] == [2, 3, 4]
        assert slot.dropped == 2

    asyncio.run(main())


def test_broadcast_fans_out_and_tracks_subscribers():
    events = []

    async def main():
        hub: Broadcast[int] = Broadcast(on_first=lambda: events.append("first"),
                                        on_last=lambda: events.append("last"))
        received = []

        async def consume():
            async for value in hub.subscribe(buffer=10):
                received.append(value)

        task = asyncio.ensure_future(consume())
        await asyncio.sleep(0)
        assert hub.subscriber_count == 1
        hub.publish(1)
        hub.publish(2)
        hub.close()
        await task
        assert received == [1, 2]

    asyncio.run(main())
    assert events == ["first", "last"]


def test_broadcast_error_reaches_subscribers():
    async def main():
        hub: Broadcast[int] = Broadcast()
        stream = hub.subscribe()
        waiting = asyncio.ensure_future(stream.__anext__())
        await asyncio.sleep(0)
        hub.close(RuntimeError("link down"))
        with pytest.raises(RuntimeError, match="link down"):
            await waiting

    asyncio.run(main())


def test_lockstep_clock_wakes_sleepers_in_order_and_waits_for_idle():
    async def main():
        clock = LockstepClock()
        woke = []

        async def sleeper(t, name):
            await clock.sleep_until(t)
            woke.append((clock.now(), name))

        tasks = [asyncio.ensure_future(sleeper(0.3, "b")),
                 asyncio.ensure_future(sleeper(0.1, "a"))]
        await clock.settle()
        assert clock.next_deadline() == pytest.approx(0.1)
        clock.advance(0.2)
        await clock.settle()
        assert woke == [(0.2, "a")]
        clock.advance(0.3)
        await asyncio.gather(*tasks)
        assert woke == [(0.2, "a"), (0.3, "b")]
        with pytest.raises(ValueError, match="back"):
            clock.advance(0.1)

    asyncio.run(main())


def test_lockstep_settle_waits_for_blocking_jobs():
    async def main():
        clock = LockstepClock()
        done = []

        async def job():
            await clock.run_blocking(lambda: sum(range(100000)))
            done.append(True)

        task = asyncio.ensure_future(job())
        await asyncio.sleep(0)
        await clock.settle()
        assert done == [True]  # settle returned only after the executor job finished
        await task

    asyncio.run(main())


def test_lockstep_wait_for_times_out_on_simulated_time():
    async def main():
        clock = LockstepClock()
        never = asyncio.get_running_loop().create_future()

        async def driver():
            while clock.now() < 5.0:
                await clock.settle()
                deadline = clock.next_deadline()
                clock.advance(deadline if deadline is not None else clock.now() + 0.1)

        drive = asyncio.ensure_future(driver())
        with pytest.raises(TimeoutError):
            await clock.wait_for(never, 2.0)
        assert clock.now() == pytest.approx(2.0)
        drive.cancel()

    asyncio.run(main())


@pytest.mark.parametrize("job_wall_s", [0.0, 0.2])
def test_lockstep_budgeted_job_takes_exactly_its_budget(job_wall_s):
    """A job with a budget lets time move on while it runs, delivers its result exactly at
    start + budget however long it really took, and time does not pass that instant before it
    has finished."""
    import threading

    async def main():
        clock = LockstepClock()
        release = threading.Event()
        results = []

        def work():
            release.wait(job_wall_s)  # a job that really takes job_wall_s of wall time
            return 42

        async def job():
            results.append((await clock.run_blocking(work, budget_s=0.05), clock.now()))

        async def stepper():  # a simulator stepping in 10 ms batches
            while clock.now() < 1.2:
                await clock.settle()
                deadline = clock.next_deadline()
                target = min(deadline if deadline is not None else 1.0, clock.now() + 0.01)
                stepped.append(target)
                await clock.jobs_done(target)
                clock.advance(target)

        stepped: list[float] = []
        clock.advance(1.0)
        task = asyncio.ensure_future(job())
        drive = asyncio.ensure_future(stepper())
        await task
        assert results == [(42, pytest.approx(1.05))]
        # time moved on while the job ran, in steps, and stopped at its deadline
        assert any(1.0 < t < 1.05 for t in stepped)
        assert pytest.approx(1.05) in stepped
        drive.cancel()

    asyncio.run(main())


def test_lockstep_budget_must_not_be_negative():
    async def main():
        with pytest.raises(ValueError, match="budget_s"):
            await LockstepClock().run_blocking(lambda: None, budget_s=-1.0)

    asyncio.run(main())


def test_a_paced_clock_held_back_stands_still_and_never_goes_back():
    from drivers.clock import PacedClock

    async def main():
        clock = PacedClock(10.0)
        before = clock.now()
        clock.hold_back(0.2)  # the world lost 0.2 s to the CPU
        during = [clock.now() for _ in range(100)]
        assert all(t == before for t in during) or min(during) >= before
        await asyncio.sleep(0.05)
        assert clock.now() == pytest.approx(before, abs=1e-3)  # still standing
        assert clock.held_back_s == pytest.approx(0.2)
        # sleeps and timeouts are on this clock: a 0.1 s sleep from now ends when it reads
        # now + 0.1, not 0.1 s of wall time later
        start = clock.now()
        await clock.sleep(0.1)
        assert clock.now() >= start + 0.1
        with pytest.raises(TimeoutError):
            await clock.wait_for(asyncio.Event().wait(), 0.05)
        # capped (the simulator computing up to there), it stands at the cap however long
        # the computing takes, and goes on from there when uncapped, without a jump
        cap = clock.now() + 0.02
        clock.cap_at(cap)
        await asyncio.sleep(0.1)
        assert clock.now() == cap
        clock.cap_at(None)
        assert clock.now() == pytest.approx(cap, abs=0.01)

    asyncio.run(main())


def test_a_late_control_tick_does_not_delay_the_next_in_real_time():
    from autopilot.runtime import next_tick_due

    period = 0.05
    # on time: the next a period later
    assert next_tick_due(1.0, 1.0, period, estimate=False, lockstep=False) == 1.05
    # 20 ms late: the next still when the schedule says (30 ms from now) ...
    assert abs(next_tick_due(1.0, 1.02, period, estimate=False, lockstep=False) - 1.05) < 1e-12
    # ... but never closer than half a period
    assert abs(next_tick_due(1.0, 1.2, period, estimate=False, lockstep=False) - 1.225) < 1e-12
    # an estimate's tick: a period from now, in real time and lockstep alike
    assert next_tick_due(1.05, 1.02, period, estimate=True, lockstep=False) == 1.07
    # lockstep: from now whatever happened
    assert next_tick_due(1.0, 1.03, period, estimate=False, lockstep=True) == 1.08
    # over many ticks each 20 ms late at random, the rate holds at 20 Hz
    import random

    rng, due, ticks = random.Random(1), 0.0, []
    for _ in range(1000):
        now = due + rng.uniform(0.0, 0.02)
        ticks.append(now)
        due = next_tick_due(due, now, period, estimate=False, lockstep=False)
    assert abs((ticks[-1] - ticks[0]) / 999 - period) < 1e-3
