"""``autopilot bench load``: its figures, table and JSON from synthetic results, and the
management of the processes it starts (pinned, always stopped)."""

from __future__ import annotations

import http.server
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from autopilot import cli, process
from autopilot.bench import load, load_figures
from autopilot.flightlog import records as ch

pytestmark = pytest.mark.serial  # busy processes, the wall clock

CORE = max(os.sched_getaffinity(0))  # (one this test process may use)


def _records(tick_times, seqs, step="follow_ball"):
    return {
        ch.CONTROL_TARGET: [{"time_s": -1.0, "step": "takeoff"}]
        + [{"time_s": t, "step": step} for t in tick_times],
        ch.detection_topic("ball"): [{"time_s": 0.01 * s, "seq": s} for s in seqs],
    }


def _summary(status="completed", reason="", rms=0.05):
    return {"status": status, "reason": reason,
            "metrics": {"latency_ms": {"p50": 40.0, "p95": 48.0, "samples": 300},
                        "follow": {"rms_range_error_m": rms, "detection_rate": 0.99}},
            "stats": {"loop_lag_p99_ms": 12.0}}


SIM_LINES = ["PX4-compatible simulated vehicle (system 8) ...",
             "[    8.00 s | 13:22:24.000] armed",
             "[   18.00 s | 13:22:34.000] mode hold → offboard",
             "[   38.00 s | 13:22:59.000] auto-disarmed after landing"]


def test_frames_the_decoder_never_got_to_count_as_shed():
    # 30 fps for 10 s (301 frames captured), but the starved decoder decoded only every
    # third: its own numbering has no gap, the capture times do
    rows = [{"time_s": 0.1 * k, "seq": k} for k in range(101)]
    assert load_figures.perception_shed(rows) == (0, 101)
    assert load_figures.perception_shed(rows, 30.0) == (200, 301)
    # decoded but not seen: the sequence's gaps, whatever the rate says
    rows = [{"time_s": k / 30.0, "seq": k} for k in range(0, 300, 2)]
    assert load_figures.perception_shed(rows, 30.0) == (149, 299)


def test_figures_of_one_load():
    ticks = [0.0, 0.03, 0.06, 0.09, 0.19]  # a 100 ms gap at the end
    seqs = [s for s in range(100, 200) if s % 10 != 5]  # 10 of the 100 delivered never seen
    viewer = {"frames": 140, "first_seq": 0, "last_seq": 599, "first_arrival_s": 5.0,
              "last_arrival_s": 15.0, "error": None}
    row = load_figures.row_from(2, _summary(), _records(ticks, seqs), viewer, SIM_LINES, 15.0)
    assert row["completed"]
    assert row["why"] is None
    assert row["tick_ms_p50"] == pytest.approx(30.0)
    assert row["tick_ms_p99"] == pytest.approx(100.0 - 0.03 * 70, abs=1e-6)  # (interpolated)
    assert row["ticks"] == 5
    assert (row["perception_shed"], row["perception_frames"]) == (10, 100)
    assert row["perception_shed_share"] == pytest.approx(0.10)
    # 10 s watched at 15 fps: 151 frames due (the camera delivered 600), 140 came
    assert (row["console_shed"], row["console_frames_due"]) == (11, 151)
    assert row["latency_ms_p95"] == 48.0
    assert row["rms_range_error_m"] == 0.05
    assert row["vehicle_real_time_factor"] == pytest.approx(30.0 / 35.0)


def test_console_due_never_exceeds_what_the_camera_delivered():
    # a vehicle behind real time delivered 50 frames in 10 s: 50 due at most, not 151
    viewer = {"frames": 50, "first_seq": 0, "last_seq": 49, "first_arrival_s": 0.0,
              "last_arrival_s": 10.0}
    assert load_figures.console_shed(viewer, 15.0) == (0, 50)
    assert load_figures.console_shed({"frames": 0, "first_seq": None}, 15.0) is None


def test_an_abort_is_a_non_completion_with_its_reason():
    reason = "telemetry stale: position 0.61 s old (limit 0.5 s)"
    row = load_figures.row_from(6, _summary("aborted", reason, rms=None), _records([0.0], []), None,
                        [], 15.0)
    assert not row["completed"]
    assert row["why"] == f"aborted: {reason}"
    assert row["tick_ms_p50"] is None
    assert row["perception_shed_share"] is None
    assert row["console_shed_share"] is None
    assert row["vehicle_real_time_factor"] is None
    # no events (it never armed): the truth log's figure stands in; the lines' win otherwise
    assert load_figures.row_from(6, None, None, None, [], 15.0, truth_real_time_factor=0.3)[
        "vehicle_real_time_factor"] == 0.3
    assert load_figures.row_from(6, None, None, None, SIM_LINES, 15.0, truth_real_time_factor=0.3)[
        "vehicle_real_time_factor"] == pytest.approx(30.0 / 35.0)
    crashed = load_figures.row_from(6, None, None, None, [], 15.0,
                            failure="the autopilot exited with code 1: Traceback")
    assert not crashed["completed"]
    assert crashed["why"].startswith("the autopilot exited")


def test_vehicle_real_time_factor_from_the_simulators_lines():
    assert load_figures.vehicle_real_time_factor(["no events"]) is None
    assert load_figures.vehicle_real_time_factor(SIM_LINES[:2]) is None  # one point only
    # across midnight
    lines = ["[    1.00 s | 23:59:55.000] armed", "[   11.00 s | 00:00:15.000] landed"]
    assert load_figures.vehicle_real_time_factor(lines) == pytest.approx(0.5)


def _row(hogs, completed, shed, tick_p99, why=None):
    return {"hogs": hogs, "completed": completed, "why": why, "tick_ms_p50": 33.0,
            "tick_ms_p99": tick_p99, "latency_ms_p50": 40.0, "latency_ms_p95": 50.0,
            "perception_shed_share": shed, "console_shed_share": 0.0,
            "rms_range_error_m": 0.05 if completed else None,
            "vehicle_real_time_factor": 1.0}


def _result(rows, rate=20.0):
    return {"mission": "follow_ball", "follow_s": 20.0, "driver": "mavsdk", "vehicle_core": 0,
            "autopilot_core": 1, "viewer_fps": 15.0, "control_rate_hz": rate, "rows": rows,
            **load_figures.conclusions(rows, rate)}


def test_the_curve_and_its_table():
    rows = [_row(0, True, 0.0, 40.0), _row(2, True, 0.05, 52.0), _row(4, True, 0.3, 70.0),
            _row(6, False, 0.6, 140.0, why="aborted: telemetry stale: position 0.9 s old")]
    result = _result(rows)
    assert result["max_hogs_completed"] == 4
    assert result["perception_sheds_from"] == 2
    assert result["control_rate_held_to"] == 4  # p99 ≤ 75 ms (1.5 periods at 20 Hz) up to 4
    assert json.loads(json.dumps(result)) == result
    table = load_figures.format_table(result)
    lines = table.splitlines()
    assert "core 0" in lines[0]
    assert "core 1" in lines[0]
    body = [line for line in lines if line.split()[1:2] in (["yes"], ["NO"])]
    assert [line.split()[0] for line in body] == ["0", "2", "4", "6"]
    assert body[1].split()[1] == "yes"
    assert body[3].split()[1] == "NO"
    assert "30.0 %" in body[2]
    assert "0.050 m" in body[0]
    assert "6 busy: aborted: telemetry stale: position 0.9 s old" in table
    assert "completed up to 4 busy processes" in table
    assert "from 2 busy" in table
    assert "up to 4 busy" in table


def test_a_load_flown_again_counts_only_when_every_flight_at_it_held():
    rows = [_row(2, True, 0.1, 60.0), _row(2, True, 0.1, 61.0),
            _row(3, True, 0.3, 70.0), _row(3, False, 0.4, 80.0, why="lost"),
            _row(3, True, 0.3, 72.0)]
    result = {**_result(rows), "repeat": 2}
    assert result["max_hogs_completed"] == 2  # one flight of three at 3 busy did not complete
    assert result["control_rate_held_to"] == 2  # nor kept its rate
    table = load_figures.format_table(result)
    assert "each load flown 2 times (a row per flight)" in table
    # the median over the flights at a load, the one not completed as infinite
    assert "2 busy 0.050 m, 3 busy 0.050 m" in table
    rows[2] = _row(3, False, 0.3, 70.0, why="lost")
    assert "3 busy fail" in load_figures.format_table({**_result(rows), "repeat": 2})


def test_the_table_says_when_nothing_was_measured_or_the_vehicle_fell_behind():
    row = {**_row(0, False, None, None, why="the vehicle did not start: EGL"),
           "tick_ms_p50": None, "vehicle_real_time_factor": 0.4}
    table = load_figures.format_table(_result([row]))
    assert "no load completed" in table
    assert "perception not measured" in table
    assert "at no load" in table
    assert "0.40× real time" in table
    assert "the vehicle did not start: EGL" in table


def test_hogs_are_parsed_and_one_core_is_refused(monkeypatch, capsys):
    assert load.parse_hogs("4") == [4]
    assert load.parse_hogs("0,2,1,2") == [0, 1, 2]
    for bad in ("", "x", "-1", "1,,a"):
        with pytest.raises(load.LoadBenchError):
            load.parse_hogs(bad)
    assert load.pick_cores([3, 1, 2]) == (1, 2)
    with pytest.raises(load.LoadBenchError, match="needs two cores"):
        load.pick_cores([5])
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    monkeypatch.setattr(process, "configure_for_flight", lambda: None)  # (this process's own)
    assert cli.main(["bench", "load", "--hogs", "0"]) == cli.EXIT_USAGE
    assert "needs two cores" in capsys.readouterr().err


def test_the_short_mission_follows_for_the_time_asked():
    text = load.short_mission(7.5)
    assert "follow_ball: {duration_s: 7.5}" in text
    assert "duration_s: 60" not in text


def _exec_done(pid: int, marker: str) -> bool:
    """The launcher has become the program (its command line holds ``marker``)."""
    try:
        line = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return False
    return marker in line and "PR_SET_PDEATHSIG" not in line  # (the launcher's own)


def _wait(condition, timeout_s: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return False


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return True
    return state in ("Z", "X")  # (a zombie is dead: its parent has not reaped it yet)


def test_hogs_are_pinned_busy_and_stopped_on_an_error():
    hogs = []

    def bench() -> None:
        with load.Processes() as procs:
            hogs.extend(procs.start_hogs(2, CORE))
            for hog in hogs:
                assert _wait(lambda pid=hog.pid: _exec_done(pid, "while os.getppid() == parent"))
                assert os.sched_getaffinity(hog.pid) == {CORE}
                assert os.getpgid(hog.pid) == hog.pid  # a session of its own: stopped as a group
            assert all(p.poll() is None for p in hogs)
            raise RuntimeError("bench failed")

    with pytest.raises(RuntimeError, match="bench failed"):
        bench()
    pids = [p.pid for p in hogs]
    assert len(set(pids)) == 2
    assert all(p.poll() is not None for p in hogs)
    assert all(_gone(pid) for pid in pids)


def test_a_child_is_stopped_by_name_and_the_rest_on_close():
    with load.Processes() as procs:
        procs.start_hogs(2, CORE)
        code = procs.stop("hog0", first=15, grace_s=5.0)
        assert code is not None
        assert procs.procs["hog1"].poll() is None
        assert procs.stop("nobody") is None
        with pytest.raises(ValueError, match="already started"):
            procs.start("hog1", load.hog_argv(), CORE)
    assert procs.procs["hog1"].poll() is not None


def test_hogs_die_with_a_bench_that_is_killed():
    # a bench process that starts a busy process and dies without cleaning up (as SIGKILL)
    code = ("import os, sys; from autopilot.bench import load; p = load.Processes(); "
            f"h = p.start_hogs(1, {CORE})[0]; print(h.pid, flush=True); "
            "sys.stdin.readline(); os._exit(0)")
    bench = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    pid = int(bench.stdout.readline())
    try:
        assert _wait(lambda: _exec_done(pid, "while os.getppid() == parent"))
        assert not _gone(pid)
        bench.stdin.write("\n")
        bench.stdin.flush()
        bench.wait(20)
        assert _wait(lambda: _gone(pid)), "the busy process outlived its bench"
    finally:
        if not _gone(pid):
            os.kill(pid, 9)


class _FakeConsole(http.server.BaseHTTPRequestHandler):
    def log_message(self, *args):
        pass

    def do_GET(self):
        if self.path.startswith("/api/status"):
            body = b'{"time_s": 1.0}'
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)
            return
        assert self.path == "/video/front.mjpg?fps=15"
        self.send_response(200)
        self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
        self.end_headers()
        for seq in (4, 6, 8, 10, 14):
            jpeg = bytes(100 + seq)
            self.wfile.write(f"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: "
                             f"{len(jpeg)}\r\nX-Frame-Seq: {seq}\r\nX-Frame-Time: 1.0\r\n"
                             "\r\n".encode() + jpeg + b"\r\n")
        self.close_connection = True


def test_the_viewer_counts_the_frames_until_the_stream_ends(tmp_path):
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _FakeConsole)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        out = tmp_path / "viewer.json"
        load.viewer_main(f"http://127.0.0.1:{server.server_address[1]}", str(out), 15.0, 10.0)
        got = json.loads(out.read_text())
    finally:
        server.shutdown()
        server.server_close()
    assert got["frames"] == 5
    assert (got["first_seq"], got["last_seq"]) == (4, 14)
    assert got["error"] is None
    assert got["last_arrival_s"] >= got["first_arrival_s"]


def test_the_viewer_gives_up_when_no_console_answers(tmp_path):
    out = tmp_path / "viewer.json"
    load.viewer_main(f"http://127.0.0.1:{load.free_tcp_port()}", str(out), 15.0, 0.3)
    assert json.loads(out.read_text())["error"] == "the console never answered"
