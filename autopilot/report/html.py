"""``autopilot report DIR``: one self-contained HTML page (plots embedded as PNG) that shows
what happened in a flight, from ``DIR/flight.mcap`` and ``DIR/summary.json``.

Plots (matplotlib, headless): top-down and side trajectories of vehicle and target; standoff
error over time; a detection timeline; target estimate against ground truth per axis with ±2σ;
commanded against actual velocity; a latency histogram. Mission steps are shaded on every time
axis. A log that was cut short (a run that crashed) gives the plots of what it holds and a
banner that says so.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import ChannelInfo, channel_counts, read_log_checked
from autopilot.report import data
from autopilot.report.panels import (
    ALWAYS,
    PANELS,
    NoData,
    panels_in_order,
    register_panel,
    shade_steps,
)


def write_report(run_dir: Path) -> Path:
    records, complete = read_log_checked(run_dir / "flight.mcap")
    summary_path = run_dir / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else None
    out = run_dir / "report.html"
    video = "onboard.mp4" if (run_dir / "onboard.mp4").is_file() else None
    out.write_text(render(records, complete, summary, title=run_dir.name,
                          channels=channel_counts(run_dir / "flight.mcap"), video=video))
    return out


def render(records, complete: bool, summary: dict | None, title: str = "flight",
           channels: Sequence[ChannelInfo] = (), video: str | None = None) -> str:
    import matplotlib

    matplotlib.use("Agg")
    phases = data.phases(records)
    targets = data.targets(records)
    sections = []
    for name, draw, target in _panels(records, targets):
        try:
            image = _figure(lambda fig, draw=draw, target=target:
                            draw(fig, records, phases, target))
        except NoData as exc:
            sections.append(f"<h2>{html.escape(name)}</h2><p class='none'>{exc}</p>")
            continue
        sections.append(f"<h2>{html.escape(name)}</h2><img alt='{html.escape(name)}' "
                        f"src='data:image/png;base64,{image}'>")
    banner = "" if complete else (
        "<p class='cut'>This log was cut short (the run did not close it, e.g. it crashed): "
        "the plots show what was written before the cut.</p>")
    table = _faults_table(records) + _metrics_table(summary)
    if video:  # beside the page, not inside it: a video is too big to embed
        table += (f"<h2>Onboard video</h2><video controls width='640' src='{html.escape(video)}'>"
                  f"</video><p><a href='{html.escape(video)}'>{html.escape(video)}</a></p>")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
            "</title><style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
            "img{max-width:100%}.cut{background:#fdd;padding:8px}.none{color:#888}"
            "td,th{padding:2px 8px;text-align:left}</style></head><body>"
            f"<h1>Flight report: {html.escape(title)}</h1>{banner}{table}"
            + "".join(sections) + _channels_table(channels) + "</body></html>")


def _faults_table(records) -> str:
    """The faults the simulator injected (a faults run: ``scenario.faults``), each with its
    window on the log's clock (a fault's ``start_s`` counts from the first arming)."""
    plan = (records.get(ch.MISSION_PLAN) or [{}])[0]
    faults = ((plan.get("scenario") or {}).get("faults")) or []
    if not faults:
        return ""
    armed = next((s["time_s"] for s in records.get(ch.VEHICLE_STATE, []) if s.get("armed")),
                 None)
    rows = []
    for f in faults:
        start = f.get("start_s") or 0.0
        end = None if f.get("duration_s") is None else start + f["duration_s"]
        if armed is not None:
            window = f"{armed + start:.1f} s – " + ("end" if end is None else
                                                      f"{armed + end:.1f} s")
        else:
            window = "never (the vehicle did not arm)"
        params = ", ".join(f"{k}={v}" for k, v in f.items()
                           if k not in ("kind", "start_s", "duration_s") and v is not None)
        rows.append(f"<tr><td>{html.escape(str(f.get('kind')))}</td><td>{window}</td>"
                    f"<td>{html.escape(params)}</td></tr>")
    return ("<h2>Injected faults</h2><table id='faults'><tr><th>kind</th><th>when (log time)"
            "</th><th>parameters</th></tr>" + "".join(rows) + "</table>")


def _channels_table(channels: Sequence[ChannelInfo]) -> str:
    """The log's channels that hold messages (a channel declared but never written is not a
    channel of this flight)."""
    channels = [c for c in channels if c.messages]
    if not channels:
        return ""
    cells = "".join(f"<tr><td>{html.escape(c.topic)}</td><td>{html.escape(c.schema)}</td>"
                    f"<td>{html.escape(c.encoding)}</td><td>{c.messages}</td></tr>"
                    for c in channels)
    return ("<h2>Log channels (flight.mcap)</h2><table id='channels'><tr><th>topic</th>"
            f"<th>schema</th><th>encoding</th><th>messages</th></tr>{cells}</table>")


def _figure(draw: Callable) -> str:
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(10, 4), dpi=90)
    try:
        draw(fig)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", bbox_inches="tight")
    finally:
        plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _trajectories(fig, records, phases, target) -> None:
    tr = data.trajectories(records, target)
    if not len(tr["vehicle"]) and not len(tr["vehicle_truth"]):
        raise NoData("no vehicle positions in this log")
    top, side = fig.subplots(1, 2)
    for key, label, style in (("vehicle_truth", "vehicle (truth)", "-"),
                              ("vehicle", "vehicle (telemetry)", "--"),
                              ("target_truth", "target (truth)", "-"),
                              ("target_estimate", "target (estimate)", ":")):
        p = tr[key]
        if len(p):
            top.plot(p[:, 1], p[:, 0], style, label=label, lw=1)
            side.plot(tr[f"{key}_t"], -p[:, 2], style, label=label, lw=1)
    top.set(xlabel="east (m)", ylabel="north (m)", title="top-down", aspect="equal")
    side.set(xlabel="time (s)", ylabel="altitude (m)", title="side")
    shade_steps(side, phases)
    top.legend(fontsize=8)


def _standoff(fig, records, phases, target) -> None:
    s = data.standoff_error(records, target)
    if not len(s["error_m"]) and not len(s["estimated_error_m"]):
        raise NoData("no target in this log")
    ax = fig.subplots()
    if len(s["error_m"]):
        ax.plot(s["t"], s["error_m"], label="true distance − standoff", lw=1)
    if len(s["estimated_error_m"]):
        ax.plot(s["estimated_t"], s["estimated_error_m"], ":", label="as the autopilot saw it",
                lw=1)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(xlabel="time (s)", ylabel="standoff error (m)")
    # scaled to the stretches the target was followed: a climb or landing before or after
    # (metres from the target) would flatten the centimetres that matter to a line
    spans = data.followed_spans(records, target)
    values = [s["error_m"][_within(s["t"], spans)],
              s["estimated_error_m"][_within(s["estimated_t"], spans)]]
    values = np.concatenate([v[np.isfinite(v)] for v in values])
    if spans and len(values):
        low, high = np.percentile(values, [0.5, 99.5])
        margin = max(0.1 * (high - low), 0.02)
        ax.set_ylim(min(low - margin, -0.02), max(high + margin, 0.02))
        note = "scaled to the following (off-scale outside it)"
    else:
        note = None
    shade_steps(ax, phases)
    ax.legend(fontsize=8, title=note, title_fontsize=7)


def _within(t: np.ndarray, spans: Sequence[tuple[float, float]]) -> np.ndarray:
    inside = np.zeros(len(t), dtype=bool)
    for a, b in spans:
        inside |= (t >= a) & (t <= b)
    return inside


def _over_target(fig, records, phases, target) -> None:
    o = data.over_target(records, target)
    if not len(o["t"]):
        raise NoData("no ground truth of the target in this log")
    top, err = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 2], "wspace": 0.45})
    # top-down, the target's centre at the origin: the part of the flight within 2 m of it
    near = np.hypot(o["offset_ne"][:, 0], o["offset_ne"][:, 1]) < 2.0
    r = target.size_m / 2.0 if target is not None else 0.5
    from matplotlib.patches import Circle

    top.add_patch(Circle((0.0, 0.0), r, fill=False, color="tab:red", lw=1, label="target"))
    if near.any():
        sc = top.scatter(o["offset_ne"][near, 1], o["offset_ne"][near, 0], c=o["height_m"][near],
                         s=2, cmap="viridis")
        fig.colorbar(sc, ax=top, label="height (m)", shrink=0.8)
        last = o["offset_ne"][-1]
        top.plot(last[1], last[0], "kx", label="last position")
    lim = max(0.6, 1.3 * r)
    top.set(xlabel="east of it (m)", ylabel="north of it (m)", title="over the target (truth)",
            xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal")
    top.legend(fontsize=7)
    err.plot(o["t"], np.hypot(o["offset_ne"][:, 0], o["offset_ne"][:, 1]), lw=1,
             label="true horizontal offset")
    if len(o["estimated_t"]):
        err.plot(o["estimated_t"], np.hypot(o["estimated_offset_ne"][:, 0],
                                            o["estimated_offset_ne"][:, 1]), ":", lw=1,
                 label="as the autopilot saw it")
    err.set_yscale("log")
    err.set(xlabel="time (s)", ylabel="m (log scale)", ylim=(0.003, 5.0),
            title="horizontal offset from the target's centre")
    shade_steps(err, phases)
    err.legend(fontsize=8)


def _detections(fig, records, phases, target) -> None:
    d = data.detection_timeline(records, target)
    if not len(d["t"]):
        raise NoData("no frames were processed")
    ax = fig.subplots()
    detected, in_view = d["detected"], d["in_view"]
    if d["has_truth"]:
        # in view (truth) on one row; below it, detected, and lost (in view, not detected)
        rows = [d["t"][in_view], d["t"][detected], d["t"][in_view & ~detected]]
        ax.eventplot(rows, lineoffsets=[2, 1, 0], colors=["tab:blue", "tab:green", "tab:red"],
                     linelengths=0.8)
        ax.set(yticks=[0, 1, 2], yticklabels=["lost (in view,\nnot detected)", "detected",
                                               "in view (truth)"])
    else:
        ax.eventplot([d["t"][detected], d["t"][~detected]], lineoffsets=[1, 0],
                     colors=["tab:green", "tab:red"], linelengths=0.8)
        ax.set(yticks=[0, 1], yticklabels=["not detected", "detected"])
    ax.set(xlabel="time (s)")
    shade_steps(ax, phases)


def _estimate(fig, records, phases, target) -> None:
    e = data.estimate_vs_truth(records, target)
    if not len(e["t"]):
        raise NoData("no target estimates in this log")
    axes = fig.subplots(1, 3)
    for i, (ax, axis) in enumerate(zip(axes, "NED", strict=True)):
        ax.fill_between(e["t"], e["estimate"][:, i] - 2 * e["std"][:, i],
                        e["estimate"][:, i] + 2 * e["std"][:, i], alpha=0.3, label="±2σ")
        ax.plot(e["t"], e["estimate"][:, i], lw=1, label="estimate")
        if np.isfinite(e["truth"][:, i]).any():
            ax.plot(e["t"], e["truth"][:, i], "k", lw=0.8, label="truth")
        ax.set(title=axis, xlabel="time (s)", ylabel="m" if i == 0 else None)
        shade_steps(ax, phases)
    axes[0].legend(fontsize=8)


def _velocity(fig, records, phases, target) -> None:
    v = data.velocity_tracking(records)
    if not len(v["actual_t"]):
        raise NoData("no telemetry in this log")
    axes = fig.subplots(1, 3)
    for i, (ax, axis) in enumerate(zip(axes, "NED", strict=True)):
        ax.plot(v["actual_t"], v["actual"][:, i], lw=1, label="actual")
        if len(v["command_t"]):
            ax.plot(v["command_t"], v["command"][:, i], lw=0.8, label="commanded")
        ax.set(title=f"v{axis.lower()}", xlabel="time (s)", ylabel="m/s" if i == 0 else None)
        shade_steps(ax, phases)
    axes[0].legend(fontsize=8)


def _latency(fig, records, phases, target) -> None:
    lat = data.latencies_ms(records)
    if not len(lat):
        raise NoData("no setpoint was computed from a frame")
    ax = fig.subplots()
    values, counts = np.unique(np.round(lat, 2), return_counts=True)
    if len(values) <= 40 and len(lat) >= 2 * len(values):  # (lockstep: the steps apart)
        step = float(np.min(np.diff(values))) if len(values) > 1 else 1.0
        ax.bar(values, counts, width=0.8 * step)
        ax.set_xlim(values[0] - step, values[-1] + step)
        ax.set_title(f"{len(values)} distinct values, a bar each (in lockstep: multiples "
                     "of the simulation step)", fontsize=8)
    else:
        ax.hist(lat, bins=min(60, max(10, int(math.sqrt(len(lat))))))
    ax.ticklabel_format(axis="x", useOffset=False)
    for q, style in ((50, "--"), (95, ":")):
        ax.axvline(np.percentile(lat, q), color="k", ls=style,
                   label=f"p{q} {np.percentile(lat, q):.1f} ms")
    ax.set(xlabel="frame capture → setpoint (ms)", ylabel="setpoints")
    ax.legend(fontsize=8)


def _path(fig, records, phases, target) -> None:
    """Top-down: the polygon, the planned path, the flown track (truth), the photo points and
    the photos' footprints (true poses); beside it, the cross-track error over time."""
    from shapely.geometry import Polygon

    from autopilot.flightlog.metrics import camera_intrinsics
    from autopilot.planning.footprint import ground_footprint
    from autopilot.planning.trajectory import cross_track_m, resample

    plans = records.get(ch.PLANNED_PATH, [])
    if not plans:
        raise NoData("no planned path in this log")
    truth = records.get(ch.GROUND_TRUTH, [])
    top, err = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.4]})
    cams = {c["name"]: c for c in records.get(ch.CAMERA_INFO, [])}
    end_times = [e["time_s"] for e in records.get(ch.MISSION_EVENTS, [])
                 if e.get("kind") in ("step_succeeded", "step_failed", "aborted")]
    t_truth = np.array([s["time_s"] for s in truth])
    p_truth = np.array([s["vehicle_position_ned_m"] for s in truth]).reshape(-1, 3)
    q_truth = np.array([s["vehicle_attitude_q"] for s in truth]).reshape(-1, 4)
    for k, plan in enumerate(plans):
        pts = np.array(plan["points_ned_m"], dtype=float)
        if plan.get("polygon"):
            rings = plan["polygon"]
            poly = Polygon(rings[0], rings[1:])
            for ring in [poly.exterior, *poly.interiors]:
                xy = np.array(ring.coords)
                top.fill(xy[:, 1], xy[:, 0], color="#cde", alpha=0.5, lw=0)
                top.plot(xy[:, 1], xy[:, 0], color="#58a", lw=1)
        start = plan["time_s"]
        stop = min([t for t in end_times if t > start] or [math.inf])
        on = (t_truth >= start) & (t_truth <= stop)
        label = f"{plan.get('step', 'step')} {plan.get('step_index', k)}"
        top.plot(pts[:, 1], pts[:, 0], "--", color="#333", lw=0.8,
                 label="planned" if k == 0 else None)
        if on.any():
            top.plot(p_truth[on, 1], p_truth[on, 0], "-", color="#d62728", lw=0.8,
                     label="flown (truth)" if k == 0 else None)
            e = cross_track_m(resample(pts, 0.02), p_truth[on])
            err.plot(t_truth[on], 100 * e, lw=0.8, label=label)
        photo_pts = np.array(plan.get("photo_points_ned_m") or []).reshape(-1, 3)
        if len(photo_pts):
            top.plot(photo_pts[:, 1], photo_pts[:, 0], "k.", ms=3,
                     label="photo points" if k == 0 else None)
        look = plan.get("look_at_ned_m")
        if look is not None:
            top.plot(look[1], look[0], "r+", ms=10)
    for photo in records.get(ch.PHOTOS, []):
        cam = cams.get(photo["camera"])
        if cam is None or not len(t_truth):
            continue
        i = min(int(np.searchsorted(t_truth, photo["time_s"])), len(t_truth) - 1)
        outline = ground_footprint(camera_intrinsics(cam), np.array(cam["rotation_body_cam"]),
                                   np.array(cam["position_body_m"]), p_truth[i], q_truth[i])
        if outline is not None:
            ring = np.vstack([outline, outline[:1]])
            top.plot(ring[:, 1], ring[:, 0], color="#2ca02c", lw=0.4, alpha=0.6)
    top.set(xlabel="east (m)", ylabel="north (m)", aspect="equal",
            title="top-down: plan, flight, photo footprints (green)")
    top.legend(fontsize=7)
    err.set(xlabel="time (s)", ylabel="cross-track error (cm)",
            title="distance from the planned path (truth)")
    shade_steps(err, phases)
    err.legend(fontsize=7)


def _status(fig, records, phases, target) -> None:
    """The mission status code over time (seed 004's codes; autopilot.status)."""
    rows = records.get(ch.MISSION_STATUS, [])
    if not rows:
        raise NoData("no mission status in this log")
    ax = fig.subplots()
    t = [r["time_s"] for r in rows]
    codes = [r["code"] for r in rows]
    end = max([t[-1], *[s["time_s"] for s in records.get(ch.VEHICLE_STATE, [])[-1:]]])
    ax.step([*t, end], [*codes, codes[-1]], where="post", color="#333")
    # each code's meaning once, in a legend-like list beside the plot, not over the line
    names = {}
    for code, r in zip(codes, rows, strict=True):
        names.setdefault(code, r.get("status", ""))
    ax.set(xlabel="time (s)", ylabel="status code", ylim=(-0.5, max(codes) + 0.5),
           yticks=sorted(names))
    ax.text(1.01, 1.0, "\n".join(f"{code}: {name}" for code, name in sorted(names.items())),
            transform=ax.transAxes, va="top", fontsize=7, color="#333")
    shade_steps(ax, phases)


for _order, (_name, _title, _draw, _per_target) in enumerate((
        ("trajectory", "Trajectories", _trajectories, False),
        ("standoff", "Standoff error", _standoff, True),
        ("over_target", "Over the target on the ground", _over_target, True),
        ("detections", "Detections", _detections, True),
        ("estimate", "Target estimate the controller flew on, against truth", _estimate, True),
        ("velocity", "Commanded and actual velocity", _velocity, False),
        ("latency", "Latency", _latency, False),
        ("path", "Planned path and flown track", _path, False),
        ("status", "Mission status", _status, False))):
    register_panel(_name, _title, _draw, per_target=_per_target, order=_order)


def _panels(records, targets: list) -> list[tuple[str, Callable, object]]:
    """The panels the flown steps' kinds ask for (every panel for a log from before per-step
    plan records), in the registry's order; target panels once per followed target."""
    from autopilot.steps import STEP_KINDS
    from autopilot.steps.metrics import plan_steps

    steps = plan_steps(records)
    wanted = set(ALWAYS)
    if steps:
        for step in steps:
            kind = STEP_KINDS.get(step["name"])
            wanted.update(kind.report if kind is not None else ())
    else:
        wanted.update(PANELS)
    first = targets[0] if targets else None
    out = []
    for panel in panels_in_order():
        if panel.name not in wanted:
            continue
        if not panel.per_target:
            out.append((panel.title, panel.draw, first))
            continue
        for target in targets or [None]:
            suffix = f" ({target.pipeline})" if target is not None and len(targets) > 1 else ""
            out.append((panel.title + suffix, panel.draw, target))
    return out


def _metrics_table(summary: dict | None) -> str:
    if not summary:
        return "<p class='none'>no summary.json (the run did not finish)</p>"
    rows = [("status", summary.get("status")), ("mission", summary.get("mission")),
            ("driver", summary.get("driver")),
            ("simulated world", (summary.get("sim") or {}).get("profile", "—")),
            ("sim time (s)", summary.get("sim_time_s")),
            ("wall time (s)", summary.get("wall_time_s"))]
    def flatten(prefix: str, values: dict) -> None:
        for key, value in values.items():
            if isinstance(value, dict):
                flatten(f"{prefix}{key}.", value)
            else:
                rows.append((f"{prefix}{key}", value))

    for group, values in (summary.get("metrics") or {}).items():
        if group != "steps" and isinstance(values, dict):
            flatten(f"{group}.", values)
    cells = "".join(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(_fmt(v))}</td></tr>"
                    for k, v in rows)
    return f"<h2>Summary</h2><table>{cells}</table>"


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return "—" if value is None else str(value)
