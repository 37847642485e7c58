"""autopilot.bench.schedule: flights spread over worker processes, in the order asked for, and
how long a batch will take said before it starts (from this machine's earlier flights)."""

from __future__ import annotations

import json
import math
import re

import pytest

from autopilot.bench import schedule
from autopilot.bench.schedule import Estimate, FlightTimes, estimate, run_ordered


def test_times_are_kept_per_kind_and_survive_a_bad_cache(tmp_path):
    path = tmp_path / "autopilot" / "flight_times.json"
    times = FlightTimes(path)
    assert times.get("a") is None
    times.add("a", 10.0)
    times.add("a", 20.0)  # half the new time, half the history
    assert times.get("a") == pytest.approx(15.0)
    times.save()
    assert FlightTimes(path).get("a") == pytest.approx(15.0)
    path.write_text("{not json", encoding="utf-8")
    assert FlightTimes(path).times == {}  # a broken cache is no cache
    path.write_text(json.dumps({"a": -1, "b": "x", "c": 3}), encoding="utf-8")
    assert FlightTimes(path).times == {"c": 3.0}


def test_an_unwritable_cache_fails_nothing(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("", encoding="utf-8")
    times = FlightTimes(blocker / "sub" / "flight_times.json")  # its parent is a file
    times.add("a", 1.0)
    times.save()


def test_the_estimate_is_the_kinds_times_over_the_workers(tmp_path):
    times = FlightTimes(tmp_path / "t.json")
    times.add("fast", 10.0)
    times.add("slow", 30.0)
    e = estimate(["fast", "slow", "slow", "fast"], 2, times)
    assert e == Estimate(4, 2, 40.0, 0)
    assert e.text() == "4 flights on 2 workers: about 40 s (from earlier flights here)"
    partly = estimate(["fast", "new"], 1, times)
    assert partly.unknown == 1
    assert "about 10 s and 1 never flown here" in partly.text()
    none = estimate(["new"], 1, times)
    assert "no earlier flight of this kind" in none.text()
    assert schedule.duration_text(600) == "10 min"
    assert schedule.duration_text(7200) == "2.0 h"


def test_kinds_tell_missions_profiles_variants_and_workers_apart():
    kinds = {schedule.kind_of("follow_ball", "realistic", "trial", 2),
             schedule.kind_of("/some/where/follow_ball.yaml", "realistic", "trial", 2),
             schedule.kind_of("follow_ball", "ideal", "trial", 2),
             schedule.kind_of("follow_ball", "realistic", "bench follow_ball", 2),
             schedule.kind_of("follow_ball", "realistic", "trial", 1)}
    assert len(kinds) == 4  # a mission file and the shipped mission of its name are one kind


def test_workers_are_one_per_usable_core_and_never_more_than_the_flights():
    assert schedule.workers_for(None, 100) == schedule.usable_cores()
    assert schedule.workers_for(8, 3) == 3
    assert schedule.workers_for(None, 1) == 1


@pytest.mark.parametrize("workers", [1, 2])
def test_results_come_back_in_the_order_asked_for_and_the_time_is_told(tmp_path, workers):
    times = FlightTimes(tmp_path / "t.json")
    said, logged = [], []
    jobs = [(x,) for x in (4.0, 9.0, 16.0, 25.0)]
    kinds = ["k"] * len(jobs)
    out = run_ordered(jobs, kinds, workers, math.sqrt, announce=said.append,
                      log=logged.append, describe=lambda i, r: f"job {i} gave {r:g}",
                      times=times)
    assert out == [2.0, 3.0, 4.0, 5.0]
    assert len(said) == 1
    assert said[0].startswith(f"4 flights on {workers} worker")
    assert "no earlier flight" in said[0]  # (a new cache)
    assert len(logged) == 4
    assert re.search(r"4/4 done in \d+ s$", logged[-1])
    assert all(line.startswith("job ") for line in logged)
    assert FlightTimes(tmp_path / "t.json").get("k") is not None  # kept for the next batch
    again: list[str] = []
    run_ordered(jobs[:2], kinds[:2], workers, math.sqrt, announce=again.append,
                times=FlightTimes(tmp_path / "t.json"))
    assert "from earlier flights here" in again[0]


def test_a_flight_that_fails_ends_the_batch_with_its_error(tmp_path):
    with pytest.raises(ValueError, match="math domain error"):
        run_ordered([(4.0,), (-1.0,)], ["k", "k"], 1, math.sqrt,
                    times=FlightTimes(tmp_path / "t.json"))


def test_a_worker_that_dies_is_a_result_when_asked_for(tmp_path):
    """(bench faults counts a crashed run as an error run, and goes on)"""
    import os

    errors: list[int] = []

    def died(i, exc):
        errors.append(i)
        return f"died: {type(exc).__name__}"

    out = run_ordered([(3,)], ["k"], 2, os._exit, on_error=died,
                      times=FlightTimes(tmp_path / "t.json"))
    assert out == ["died: BrokenProcessPool"]
    assert errors == [0]
    assert FlightTimes(tmp_path / "t.json").get("k") is None  # no time kept for it


def test_the_time_is_the_flights_laid_out_on_the_workers(tmp_path):
    assert schedule.makespan([15.0, 15.0, 15.0], 2) == 30.0  # (the third waits for a worker)
    assert schedule.makespan([30.0, 10.0, 10.0, 10.0], 2) == 30.0
    assert schedule.makespan([], 2) == 0.0
    times = FlightTimes(tmp_path / "t.json")
    times.add("k", 15.0)
    assert estimate(["k"] * 3, 2, times).seconds == 30.0
    progress = schedule.Progress(["k", "k", "k"], 2, times)
    assert progress.flown(0, 15.0) == "1/3 done, about 15 s left"  # two left, on two workers
    new = schedule.Progress(["a", "b"], 1, FlightTimes(tmp_path / "u.json"))
    assert new.flown(0, None) == "1/2 done"  # (nothing known to tell the time by)
