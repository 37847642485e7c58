"""Where the CPU goes (drivers.stages): each stage's own CPU time on the thread that did the
work, a stage within a stage charged to the inner one only, nothing counted while off, and
the bench's summary and bound from those counts."""

from __future__ import annotations

import hashlib
import os
import threading
import time

import pytest

from autopilot.bench.speed import bound, stage_summary
from drivers.stages import Stages


def spin(seconds: float) -> None:
    """Burn this thread's CPU for ``seconds`` of its own CPU time."""
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def spin_without_the_gil(seconds: float) -> None:
    """Burn this thread's CPU for ``seconds`` of its own CPU time in hashing, which lets the GIL
    go: two such threads are both runnable at once, as native work (Mesa, OpenCV) is."""
    block = bytes(1 << 20)
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        hashlib.sha256(block).digest()


def test_a_stage_counts_its_own_cpu_time_not_an_inner_stages() -> None:
    stages = Stages()
    stages.start()
    with stages.stage("outer"):
        spin(0.02)
        with stages.stage("inner"):
            spin(0.03)
        spin(0.01)
    counted = stages.stop()
    assert counted["outer"] == pytest.approx(0.03, abs=0.008)
    assert counted["inner"] == pytest.approx(0.03, abs=0.008)


def test_waiting_costs_nothing_and_each_thread_counts_its_own() -> None:
    stages = Stages()
    stages.start()

    done, leave = threading.Event(), threading.Event()

    def worker() -> None:
        with stages.stage("work"):
            spin(0.03)
        spin(0.02)  # (not in a stage: the thread's whole CPU time counts it)
        done.set()
        leave.wait()

    thread = threading.Thread(target=worker, name="worker_0")
    with stages.stage("waiting"):
        thread.start()
        done.wait()  # (blocked: no CPU of this thread's)
    counted = stages.stop()
    leave.set()
    thread.join()
    assert counted["work"] == pytest.approx(0.03, abs=0.008)
    assert counted["waiting"] < 0.01
    assert stages.threads()["worker"] == pytest.approx(0.05, abs=0.01)


def test_nothing_is_counted_while_off_and_a_start_forgets_the_last_count() -> None:
    stages = Stages()
    with stages.stage("off"):
        spin(0.01)
    assert stages.totals() == {}
    stages.start()
    with stages.stage("a"):
        spin(0.01)
    stages.stop()
    stages.start()
    with stages.stage("b"):
        spin(0.01)
    counted = stages.stop()
    assert counted.get("a", 0.0) == 0.0
    assert counted["b"] > 0.005


def test_the_summary_keeps_what_no_stage_counted_and_scales_per_simulated_second() -> None:
    s = stage_summary({"physics": 1.0, "rasteriser": 2.0}, {"MainThread": 1.0, "render": 0.5},
                      sim_time_s=10.0, wall_s=5.0, process_cpu_s=4.0)
    assert s["cpu_s"]["other"] == pytest.approx(1.0)
    assert s["ms_per_sim_s"]["physics"] == pytest.approx(100.0)
    assert s["ms_per_sim_s"]["other"] == pytest.approx(100.0)


def test_the_bound_is_the_cpu_when_the_cores_are_busy_else_the_busiest_thread() -> None:
    busy = stage_summary({"physics": 1.0}, {"MainThread": 5.0, "render": 4.0}, 20.0, 5.0, 9.0)
    assert bound(busy, cores=2).startswith("CPU-bound")
    idle = stage_summary({"rasteriser": 2.0}, {"MainThread": 2.0, "render": 2.5}, 20.0, 5.0,
                         6.5)
    text = bound(idle, cores=2)
    assert text.startswith("serial path: the render thread (with the rasteriser) busy 90 %")
    # cores idle on average while its threads queued for one: the work comes in bursts
    bursty = stage_summary({"rasteriser": 2.0}, {"MainThread": 2.0, "render": 2.5}, 20.0, 5.0,
                           6.5, run_queue_wait_s=4.0)
    text = bound(bursty, cores=2)
    assert text.startswith("bursts: 1.30 of 2 cores busy on average, yet its threads waited "
                           "0.80 s a second for a core")
    assert "render thread (with the rasteriser) busy 90 %" in text
    calm = stage_summary({}, {"MainThread": 2.0}, 20.0, 5.0, 2.5, run_queue_wait_s=0.5)
    assert bound(calm, cores=2).startswith("serial path: the MainThread thread")


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs Linux affinity")
def test_the_run_queue_wait_is_counted_while_counting() -> None:
    """Two threads hashing on one core (the GIL let go) take turns: each waits for the other
    about half the time, and the wait is counted."""
    stages = Stages()
    cpus = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cpus)})  # (this thread; the spinner inherits it)
    try:
        stages.start()
        other = threading.Thread(target=spin_without_the_gil, args=(0.1,))
        other.start()
        spin_without_the_gil(0.1)
        other.join()
        stages.stop()
    finally:
        os.sched_setaffinity(0, cpus)
    waited = stages.run_queue_wait_s()
    assert waited is not None
    assert waited >= 0.05


def test_the_table_ranks_the_stages_and_says_a_failed_flight() -> None:
    from autopilot.bench.speed import format_table

    cell = {"status": "completed", "real_time_factor": 3.0, "cpu_ms_per_sim_s": 500.0,
            "process_cpu_s": 35.0, "wall_s": 23.0, "bound": "CPU-bound: …",
            "stages_ms_per_sim_s": {"physics": 50.0, "rasteriser": 150.0, "other": 100.0}}
    failed = {"status": "error", "reason": "exit 1"}
    text = format_table({"cores": 2, "missions": {
        "follow_ball": {"profiles": {"realistic": cell, "ideal": failed}}}})
    assert "follow_ball (realistic): × 3.00 real time, 500 ms CPU" in text
    assert "rasteriser 150 (30 %), other 100 (20 %), physics 50 (10 %)" in text
    assert "follow_ball (ideal): error (exit 1)" in text


def test_a_thread_that_has_ended_is_not_a_crash() -> None:
    """Sampling every thread's CPU time while threads end (pools shutting down at the end of a
    flight) once crashed ``autopilot run --stages`` (SIGSEGV in pthread_getcpuclockid, asked
    for a thread ending as it was asked: a race no test makes happen at will). Threads are now
    read in /proc by their kernel id: one listed that has ended is skipped, the others are
    counted. In a process of its own, so that a crash would be a failure."""
    import subprocess
    import sys

    code = """if True:
        import threading
        from drivers import stages as module
        ended = threading.Thread(target=lambda: None)
        ended.start()
        ended.join()
        listed = threading.enumerate
        module.threading.enumerate = lambda: [*listed(), ended]
        s = module.Stages()
        s.start()
        s.sample_threads()
        print(sorted(name for name, _ in s._thread_ns.values()))
    """
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "MainThread" in out.stdout
