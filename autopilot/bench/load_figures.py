"""The load bench's figures from a flight's records and lines: the control tick's intervals,
frames shed by perception and by the console, the vehicle's real-time factor, a row per
number of busy processes, the conclusions, and the table."""

from __future__ import annotations

import itertools
import math
import re
import statistics
from collections.abc import Iterable, Mapping, Sequence

#: shed above this share of frames counts as shedding (a frame now and then is noise, and the
#: camera itself drops ~1 % on the realistic profile: counted too, since the capture times'
#: span cannot tell them apart)
SHED_SHARE = 0.03
#: the control loop keeps its rate while its tick interval's p99 stays within this many periods
TICK_P99_PERIODS = 1.5
#: the vehicle keeps real time above this factor
VEHICLE_REAL_TIME = 0.95

# What the bench's children run first: pin to a core, die with the bench, optionally lower
# (numerically) the niceness, then become the real program. A launcher rather than Popen's
# preexec_fn: nothing runs between fork and exec in the bench's own process.
def _percentile(values: Sequence[float], q: float) -> float | None:
    if not len(values):
        return None
    import numpy as np

    return float(np.percentile(values, q))


def tick_intervals_ms(records: Iterable[Mapping], step: str = "follow_ball") -> list[float]:
    """Intervals between the control ticks of ``step`` (one ``/control/target`` record each)."""
    times = [r["time_s"] for r in records if r.get("step") == step]
    return [1e3 * (b - a) for a, b in itertools.pairwise(times)]


def perception_shed(records: Iterable[Mapping], camera_rate_hz: float | None = None
                    ) -> tuple[int, int]:
    """(frames shed, frames delivered) over the processed frames' span. The decoder numbers
    the frames it decodes, so a gap in the sequence is a decoded frame detection never saw;
    frames the decoder itself never got to (a starved decoder's socket overflows) leave no
    gap, so with ``camera_rate_hz`` the camera's own count over the span of capture times is
    the floor of what was delivered."""
    rows = [r for r in records if r.get("seq") is not None]
    seqs = sorted({int(r["seq"]) for r in rows})
    if not seqs:
        return 0, 0
    delivered = seqs[-1] - seqs[0] + 1
    times = [float(r["time_s"]) for r in rows if r.get("time_s") is not None]
    if camera_rate_hz and len(times) > 1:
        delivered = max(delivered, round((max(times) - min(times)) * camera_rate_hz) + 1)
    return delivered - len(seqs), delivered


def console_shed(viewer: Mapping, fps: float) -> tuple[int, int] | None:
    """(frames shed, frames due) for the viewer: due at its rate over the time it watched, but
    never more than the camera delivered then (sequence numbers); None if it saw nothing."""
    if not viewer.get("frames") or viewer.get("first_seq") is None:
        return None
    delivered = viewer["last_seq"] - viewer["first_seq"] + 1
    watched_s = viewer["last_arrival_s"] - viewer["first_arrival_s"]
    due = min(delivered, round(fps * watched_s) + 1)
    return max(0, due - viewer["frames"]), due


_EVENT = re.compile(r"^\[\s*([0-9.]+) s \| (\d\d):(\d\d):(\d\d(?:\.\d+)?)\]")


def vehicle_real_time_factor(lines: Iterable[str]) -> float | None:
    """Simulated over wall time between the first and the last of ``autopilot sim``'s event
    lines (``[  12.34 s | 13:20:01.123] armed``); None with fewer than two, or too close."""
    points = []
    for line in lines:
        m = _EVENT.match(line)
        if m:
            wall = int(m[2]) * 3600 + int(m[3]) * 60 + float(m[4])
            points.append((float(m[1]), wall))
    if len(points) < 2:
        return None
    (s0, w0), (s1, w1) = points[0], points[-1]
    wall = (w1 - w0) % 86400  # (past midnight)
    return (s1 - s0) / wall if wall >= 5.0 else None


def _share(pair: tuple[int, int] | None) -> float | None:
    return None if pair is None or not pair[1] else pair[0] / pair[1]


def row_from(hogs: int, summary: Mapping | None, records: Mapping | None,
             viewer: Mapping | None, sim_lines: Sequence[str], fps: float,
             failure: str | None = None, truth_real_time_factor: float | None = None,
             camera_rate_hz: float | None = None) -> dict:
    """One load's figures from its run's summary and log records, the viewer's result and the
    simulator's output; ``failure`` says why the run gave no summary (if it did not).
    ``truth_real_time_factor`` stands in for the vehicle's when its lines do not give it (a
    flight that ended before the vehicle armed)."""
    from autopilot.flightlog import records as ch

    records = records or {}
    ticks = tick_intervals_ms(records.get(ch.CONTROL_TARGET, []))
    shed = perception_shed(records.get(ch.detection_topic("ball"), []), camera_rate_hz)
    console = console_shed(viewer, fps) if viewer else None
    metrics = (summary or {}).get("metrics", {})
    latency = metrics.get("latency_ms", {})
    follow = metrics.get("follow", {})
    completed = summary is not None and summary.get("status") == "completed"
    if summary is None:
        why = failure or "no summary"
    elif completed:
        why = None
    else:
        why = f"{summary.get('status')}: {summary.get('reason') or 'no reason given'}"
    return {
        "hogs": hogs,
        "completed": completed,
        "why": why,
        "tick_ms_p50": _percentile(ticks, 50),
        "tick_ms_p99": _percentile(ticks, 99),
        "ticks": len(ticks) + 1 if ticks else 0,
        "latency_ms_p50": latency.get("p50"),
        "latency_ms_p95": latency.get("p95"),
        "perception_shed": shed[0],
        "perception_frames": shed[1],
        "perception_shed_share": _share(shed),
        "console_shed": console[0] if console else None,
        "console_frames_due": console[1] if console else None,
        "console_shed_share": _share(console),
        "viewer_error": (viewer or {}).get("error"),
        "rms_range_error_m": follow.get("rms_range_error_m"),
        "detection_rate": follow.get("detection_rate"),
        "vehicle_real_time_factor": vehicle_real_time_factor(sim_lines)
        or truth_real_time_factor,
        "loop_lag_p99_ms": (summary or {}).get("stats", {}).get("loop_lag_p99_ms"),
    }


def conclusions(rows: Sequence[Mapping], control_rate_hz: float) -> dict:
    """The curve's landmarks: the highest load that completed, the lowest at which perception
    sheds, the highest up to which control kept its rate (every load up to it)."""
    by_load = sorted(rows, key=lambda r: r["hogs"])
    limit_ms = TICK_P99_PERIODS * 1e3 / control_rate_hz
    loads = sorted({r["hogs"] for r in by_load})
    # a load completed when every flight at it did (a load flown once: that flight)
    completed = [n for n in loads if all(r["completed"] for r in by_load if r["hogs"] == n)]
    measured = [r for r in by_load if r["perception_shed_share"] is not None]
    shedding = [r["hogs"] for r in measured if r["perception_shed_share"] > SHED_SHARE]
    held = None
    for n in loads:
        if any(r["tick_ms_p99"] is None or r["tick_ms_p99"] > limit_ms
               for r in by_load if r["hogs"] == n):
            break
        held = n
    return {"max_hogs_completed": max(completed) if completed else None,
            "perception_measured": bool(measured),
            "perception_sheds_from": min(shedding) if shedding else None,
            "control_rate_held_to": held, "tick_p99_limit_ms": limit_ms}


# ----------------------------------------------------------------------------------------------
# the bench
# ----------------------------------------------------------------------------------------------

def format_table(r: Mapping) -> str:
    def num(x, fmt="{:.0f}"):
        return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)

    def pct(x):
        return "–" if x is None else f"{100 * x:.1f} %"

    head = (f"{'busy':>4}  {'completed':<9}  {'tick ms p50/p99':>15}  "
            f"{'glass→setpoint ms p50/p95':>25}  {'perception shed':>15}  "
            f"{'console shed':>12}  {'range RMS':>9}  {'vehicle':>7}")
    lines = [
        f"load: follow_ball ({r['follow_s']:g} s following) in real time over "
        f"{r['driver']}, H.264 video; the vehicle alone on core {r['vehicle_core']}, the "
        f"autopilot, a console viewer ({r['viewer_fps']:g} fps MJPEG) and N busy processes "
        f"on core {r['autopilot_core']}",
        head, "-" * len(head)]
    notes = []
    for row in r["rows"]:
        rtf = row["vehicle_real_time_factor"]
        lines.append(
            f"{row['hogs']:>4}  {'yes' if row['completed'] else 'NO':<9}  "
            f"{num(row['tick_ms_p50']) + ' / ' + num(row['tick_ms_p99']):>15}  "
            f"{num(row['latency_ms_p50']) + ' / ' + num(row['latency_ms_p95']):>25}  "
            f"{pct(row['perception_shed_share']):>15}  {pct(row['console_shed_share']):>12}  "
            f"{num(row['rms_range_error_m'], '{:.3f} m'):>9}  "
            f"{num(rtf, '{:.2f}×'):>7}")
        if row["why"]:
            notes.append(f"  {row['hogs']} busy: {row['why']}")
        if rtf is not None and rtf < VEHICLE_REAL_TIME:
            notes.append(f"  {row['hogs']} busy: the vehicle ran at {rtf:.2f}× real time (its "
                         "core was not its own): its telemetry looked old for that reason")
    lines += notes
    completed, sheds, held = (r["max_hogs_completed"], r["perception_sheds_from"],
                              r["control_rate_held_to"])
    lines += [
        f"completed up to {completed} busy processes" if completed is not None
        else "no load completed",
        (f"perception sheds over {100 * SHED_SHARE:g} % of frames from {sheds} busy"
         if sheds is not None else "perception shed no more than "
         f"{100 * SHED_SHARE:g} % of frames at any load" if r["perception_measured"]
         else "perception not measured (no flight reached the follow step)")
        + "; control kept its rate (tick p99 ≤ "
        f"{r['tick_p99_limit_ms']:.0f} ms) " + (f"up to {held} busy" if held is not None
                                                else "at no load"),
        "(tick: the control step, at least "
        f"{r['control_rate_hz']:g} Hz and on every estimate; vehicle: its real-time factor)"]
    if r.get("repeat", 1) > 1:
        lines.insert(-1, f"each load flown {r['repeat']} times (a row per flight); median "
                     "range RMS, a flight not completed counted as infinite: "
                     + ", ".join(f"{n} busy {_median_rms(r['rows'], n)}"
                                 for n in sorted({row["hogs"] for row in r["rows"]})))
    return "\n".join(lines)


def _median_rms(rows: Sequence[Mapping], hogs: int) -> str:
    value = statistics.median(row["rms_range_error_m"] if row["completed"]
                              and row["rms_range_error_m"] is not None else math.inf
                              for row in rows if row["hogs"] == hogs)
    return "fail" if math.isinf(value) else f"{value:.3f} m"
