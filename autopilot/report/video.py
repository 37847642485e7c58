"""The drone's-eye video of a flight: a camera's logged frames with what the autopilot saw and
decided drawn over them, written to ``DIR/onboard.mp4`` (H.264).

Everything drawn comes from the flight log, as the autopilot had it (never ground truth):

* the detection (circle and centre) and, dashed, where the tracker told the detector to look;
* the target estimate projected into the image with the vehicle's logged pose, and its ±2σ
  position uncertainty as an ellipse (the covariance pushed through the projection's Jacobian);
* the commanded velocity in the body frame (an arrow: up the image is forward) and yaw rate;
* time, mission step and phase, and a ``name::value`` panel of key values (seed 000's console).

:func:`overlay_at` extracts what to draw at one instant and :func:`draw_overlay` draws it: both
plain functions of their inputs, tested on their own.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from autopilot.config import InputError
from autopilot.estimation.pose_history import slerp
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_images, read_log_checked
from autopilot.flightlog.metrics import pixel_of
from drivers.geometry import quat_to_matrix

Records = Mapping[str, Sequence[Mapping]]
ESTIMATE_MAX_AGE_S = 1.0  # an estimate older than this is not drawn
GREEN, YELLOW, CYAN, WHITE, RED = (60, 220, 60), (0, 220, 255), (255, 220, 0), (255, 255, 255), \
    (40, 40, 240)


class VideoError(InputError):
    pass


@dataclass(frozen=True, slots=True)
class Ellipse:
    centre_px: tuple[float, float]
    half_axes_px: tuple[float, float]
    angle_deg: float


@dataclass(frozen=True, slots=True)
class Overlay:
    """What is drawn over one frame."""

    time_s: float
    step: str = ""
    phase: str = ""
    detection_px: tuple[float, float, float] | None = None  # u, v, radius
    #: the detection's outline when it has corners (a marker's, in its corner order)
    outline_px: tuple[tuple[float, float], ...] | None = None
    hint_px: tuple[float, float, float] | None = None
    estimate_px: tuple[float, float] | None = None
    estimate_ellipse: Ellipse | None = None
    command_frd_m_s: tuple[float, float, float] | None = None  # forward, right, down
    command_yaw_rate_deg_s: float | None = None
    panel: tuple[tuple[str, str], ...] = field(default_factory=tuple)


# ----------------------------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------------------------


def project_with_covariance(camera: Mapping, vehicle_p: np.ndarray, vehicle_q: np.ndarray,
                            point_ned: np.ndarray, cov_ned: np.ndarray,
                            sigmas: float = 2.0) -> tuple[tuple[float, float], Ellipse] | None:
    """Pixel of a world point in a camera, and the ``sigmas``-σ ellipse of its position
    covariance (first-order: J Σ Jᵀ); None when the point is not in front of the camera."""
    r_bc = np.array(camera["rotation_body_cam"], dtype=float).reshape(3, 3)
    a = r_bc.T @ quat_to_matrix(vehicle_q).T  # NED → optical
    p = a @ (point_ned - vehicle_p) - r_bc.T @ np.array(camera["position_body_m"], dtype=float)
    x, y, z = p
    if z <= 0.05:
        return None
    fx, fy = camera["fx"], camera["fy"]
    u, v = pixel_of(camera, p)  # where the lens puts it (the image is not undistorted)
    jac = np.array([[fx / z, 0.0, -fx * x / z ** 2], [0.0, fy / z, -fy * y / z ** 2]]) @ a
    cov_px = jac @ cov_ned @ jac.T
    values, vectors = np.linalg.eigh(0.5 * (cov_px + cov_px.T))
    values = np.clip(values, 0.0, None)
    major = vectors[:, 1]
    ellipse = Ellipse((float(u), float(v)),
                      (float(sigmas * math.sqrt(values[1])), float(sigmas * math.sqrt(values[0]))),
                      float(math.degrees(math.atan2(major[1], major[0]))))
    return (float(u), float(v)), ellipse


class _Series:
    """Rows of one channel, looked up by time (the last at or before)."""

    def __init__(self, rows: Sequence[Mapping]) -> None:
        self.rows = sorted(rows, key=lambda r: r["time_s"])
        self.times = [r["time_s"] for r in self.rows]

    def at_or_before(self, time_s: float) -> Mapping | None:
        i = bisect.bisect_right(self.times, time_s + 1e-9)
        return self.rows[i - 1] if i else None

    def bracket(self, time_s: float) -> tuple[Mapping, Mapping, float] | None:
        i = bisect.bisect_right(self.times, time_s)
        if i == 0 or i == len(self.rows):
            return None
        a, b = self.rows[i - 1], self.rows[i]
        span = b["time_s"] - a["time_s"]
        return a, b, (time_s - a["time_s"]) / span if span > 0 else 0.0


class OverlaySource:
    """What to draw at any instant of a flight, from its log records."""

    def __init__(self, records: Records, camera: str) -> None:
        cams = {c["name"]: c for c in records.get(ch.CAMERA_INFO, [])}
        self.camera = cams.get(camera)
        # the first pipeline that read this camera: its detections and estimates are drawn
        pipeline = next((topic for topic in ch.detection_topics(records)
                         if any(r.get("camera") == camera for r in records[topic])), None)
        rows = records.get(pipeline, []) if pipeline is not None else []
        name = pipeline.rsplit("/", 1)[-1] if pipeline is not None else None
        self.detections = {ch.time_key(r["time_s"]): r for r in rows if r["camera"] == camera}
        self.states = _Series(records.get(ch.VEHICLE_STATE, []))
        self.estimates = _Series([e for e in records.get(ch.TARGET_ESTIMATES, [])
                                  if e.get("pipeline", name) == name])
        self.setpoints = _Series(records.get(ch.SETPOINTS, []))
        self.events = _Series(records.get(ch.MISSION_EVENTS, []))

    def pose_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, Mapping] | None:
        found = self.states.bracket(time_s)
        if found is None:
            last = self.states.at_or_before(time_s)
            if last is None or time_s - last["time_s"] > 0.1:
                return None
            return ch.vec(last["position_ned_m"]), ch.vec(last["attitude_q"]), last
        a, b, f = found
        pa, pb = ch.vec(a["position_ned_m"]), ch.vec(b["position_ned_m"])
        return pa + f * (pb - pa), slerp(ch.vec(a["attitude_q"]), ch.vec(b["attitude_q"]), f), b

    def overlay_at(self, time_s: float) -> Overlay:
        setpoint = self.setpoints.at_or_before(time_s)
        step = setpoint["step"] if setpoint else ""
        phase = setpoint["phase"] if setpoint else ""
        event = self.events.at_or_before(time_s)
        if event is not None and (not setpoint or event["time_s"] > setpoint["time_s"]):
            step = event.get("step") or step
        return overlay_from(time_s, self.camera, self.detections.get(ch.time_key(time_s)),
                            self.pose_at(time_s), self.estimates.at_or_before(time_s),
                            setpoint, step, phase)


def overlay_from(time_s: float, camera: Mapping | None, det: Mapping | None,
                 pose: tuple[np.ndarray, np.ndarray, Mapping] | None, est: Mapping | None,
                 setpoint: Mapping | None, step: str, phase: str) -> Overlay:
    """What to draw over a frame captured at ``time_s``, from records as the flight log keeps
    them (the detection in it, the vehicle's pose then, the newest target estimate and
    setpoint): the same for a logged flight's video and for the console's live one."""
    detection = hint = outline = None
    panel: list[tuple[str, str]] = []
    if det is not None:
        if det["detected"]:
            detection = (det["u_px"], det["v_px"], det["radius_px"])
            corners = det.get("corners_px")
            if corners:
                outline = tuple((float(corners[i]), float(corners[i + 1]))
                                for i in range(0, len(corners) - 1, 2))
            what = f"id {det['marker_id']}" if det.get("marker_id") is not None else \
                f"score {det['score']:.2f}" if det.get("score") is not None else "found"
            panel += [("det", f"{what}, r {det['radius_px']:.1f} px"),
                      ("range", f"{det['range_m']:.2f} m (detection)")]
        else:
            panel.append(("det", "none"))
        if det.get("hint_u_px") is not None:
            hint = (det["hint_u_px"], det["hint_v_px"], det["hint_radius_px"])
    estimate_px = ellipse = None
    if pose is not None:
        p_v, q_v, state = pose
        panel += [("mode", state["mode"]), ("alt", f"{-p_v[2]:.2f} m")]
        if state.get("battery_remaining") is not None:
            panel.append(("battery", f"{100 * state['battery_remaining']:.0f} %"))
        if est is not None and time_s - est["time_s"] <= ESTIMATE_MAX_AGE_S \
                and camera is not None:
            dt = time_s - est["time_s"]
            p_t = ch.vec(est["position_ned_m"]) + dt * ch.vec(est["velocity_ned_m_s"])
            cov = ch.vec(est["position_cov_m2"]).reshape(3, 3) if est.get("position_cov_m2") \
                else np.diag(ch.vec(est["position_std_m"]) ** 2)
            cov = cov + np.diag(ch.vec(est["velocity_std_m_s"]) ** 2) * dt * dt
            projected = project_with_covariance(camera, p_v, q_v, p_t, cov)
            if projected is not None:
                estimate_px, ellipse = projected
            panel += [("target", f"{np.linalg.norm(p_t - p_v):.2f} m (estimate)"),
                      ("sigma", f"{np.sqrt(np.trace(cov) / 3) * 100:.1f} cm")]
    command = yaw_rate = None
    if setpoint is not None and time_s - setpoint["time_s"] <= 1.0:
        vel = ch.vec(setpoint["velocity_m_s"])
        if np.all(np.isfinite(vel)):
            if setpoint["frame"] != "body_frd" and pose is not None:
                vel = quat_to_matrix(pose[1]).T @ vel  # NED → body FRD
            command = (float(vel[0]), float(vel[1]), float(vel[2]))
        rate = ch.num(setpoint.get("yaw_rate_rad_s"))
        yaw_rate = math.degrees(rate) if math.isfinite(rate) else None
        if setpoint.get("latency_ms") is not None:
            panel.append(("latency", f"{setpoint['latency_ms']:.0f} ms"))
    return Overlay(time_s, step, phase, detection, outline, hint, estimate_px, ellipse,
                   command, yaw_rate, tuple(panel))


# ----------------------------------------------------------------------------------------------
# Drawing
# ----------------------------------------------------------------------------------------------

_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _text(image: np.ndarray, text: str, org: tuple[int, int], colour=WHITE,
          scale: float = 0.45) -> None:
    """Text on a darkened box (readable over sky and ground alike)."""
    (tw, th), base = cv2.getTextSize(text, _FONT, scale, 1)
    x, y = org
    x0, y0 = max(0, x - 3), max(0, y - th - 3)
    x1, y1 = min(image.shape[1], x + tw + 3), min(image.shape[0], y + base + 2)
    if x1 > x0 and y1 > y0:
        image[y0:y1, x0:x1] = (image[y0:y1, x0:x1] * 0.35).astype(np.uint8)
    cv2.putText(image, text, org, _FONT, scale, colour, 1, cv2.LINE_AA)


def _pt(u: float, v: float) -> tuple[int, int]:
    return round(u), round(v)


def draw_overlay(image_bgr: np.ndarray, overlay: Overlay) -> np.ndarray:
    """A copy of the frame with ``overlay`` drawn over it."""
    out = image_bgr.copy()
    h, w = out.shape[:2]
    if overlay.hint_px is not None:
        u, v, r = overlay.hint_px
        half = int(max(48.0, 3.0 * r))
        x, y = _pt(u, v)
        for i in range(0, 2 * half, 12):  # dashed square: the detector's search window
            cv2.line(out, (x - half + i, y - half), (x - half + min(i + 6, 2 * half), y - half),
                     CYAN, 1)
            cv2.line(out, (x - half + i, y + half), (x - half + min(i + 6, 2 * half), y + half),
                     CYAN, 1)
    if overlay.estimate_ellipse is not None:
        e = overlay.estimate_ellipse
        axes = (max(1, round(e.half_axes_px[0])), max(1, round(e.half_axes_px[1])))
        if max(axes) < 4 * (w + h):
            cv2.ellipse(out, _pt(*e.centre_px), axes, e.angle_deg, 0, 360, YELLOW, 1,
                        cv2.LINE_AA)
    if overlay.estimate_px is not None:
        x, y = _pt(*overlay.estimate_px)
        cv2.drawMarker(out, (x, y), YELLOW, cv2.MARKER_TILTED_CROSS, 12, 2, cv2.LINE_AA)
    if overlay.outline_px:
        points = np.round(np.asarray(overlay.outline_px)).astype(np.int32)
        cv2.polylines(out, [points], True, GREEN, 2, cv2.LINE_AA)
        cv2.circle(out, tuple(int(x) for x in points[0]), 4, RED, -1)  # the first corner
    if overlay.detection_px is not None:
        u, v, r = overlay.detection_px
        if not overlay.outline_px:
            cv2.circle(out, _pt(u, v), max(1, round(r)), GREEN, 2, cv2.LINE_AA)
        cv2.drawMarker(out, _pt(u, v), GREEN, cv2.MARKER_CROSS, 10, 1, cv2.LINE_AA)
    # commanded velocity: an arrow from the bottom centre, forward = up the image
    if overlay.command_frd_m_s is not None:
        fwd, right, down = overlay.command_frd_m_s
        base = (w // 2, h - 40)
        scale = 25.0  # px per m/s
        tip = (int(base[0] + scale * right), int(base[1] - scale * fwd))
        cv2.circle(out, base, 3, RED, -1)
        cv2.arrowedLine(out, base, tip, RED, 2, cv2.LINE_AA, tipLength=0.25)
        rate = overlay.command_yaw_rate_deg_s
        _text(out, f"cmd fwd {fwd:+.2f} right {right:+.2f} down {down:+.2f} m/s"
              + (f"  yaw {rate:+.0f} deg/s" if rate is not None else ""),
              (max(4, w // 2 - 190), h - 10), (90, 90, 255))
    header = f"{overlay.time_s:7.2f} s  {overlay.step or '-'}" + \
        (f" / {overlay.phase}" if overlay.phase else "")
    _text(out, header, (6, 18), WHITE, 0.55)
    for i, (name, value) in enumerate(overlay.panel):
        _text(out, f"{name}::{value}", (6, 42 + 17 * i), WHITE, 0.42)
    return out


# ----------------------------------------------------------------------------------------------
# The video
# ----------------------------------------------------------------------------------------------


def write_video(run_dir: Path, camera: str | None = None, out: Path | None = None,
                crf: int = 23) -> tuple[Path, int]:
    """``run_dir/onboard.mp4`` from ``run_dir/flight.mcap``: the camera's logged frames (the
    followed camera's by default) at their rate, with overlays. Returns its path and the
    number of frames."""
    import av

    path = run_dir / "flight.mcap"
    if not path.is_file():
        raise VideoError(f"{path}: no such file")
    records, _ = read_log_checked(path)
    plan = (records.get(ch.MISSION_PLAN) or [{}])[0]
    used = [p["camera"] for step in plan.get("steps", []) if isinstance(step, Mapping)
            for p in step.get("pipelines") or []]
    camera = camera or (used[0] if used else plan.get("camera")) or "front"
    source = OverlaySource(records, camera)
    times = [im.time_s for im in read_images(path, camera)]
    if not times:
        logged = sorted({c["name"] for c in records.get(ch.CAMERA_INFO, [])})
        raise VideoError(f"{path}: no logged frames of camera {camera!r} (frames are logged "
                         f"with log.frames.*_rate_hz; cameras with info: {logged})")
    # the camera's rate when every frame was logged; else the rate they were logged at
    info = source.camera or {}
    period = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    camera_rate = float(info.get("rate_hz") or 0.0)
    if camera_rate > 0 and (period == 0.0 or abs(period * camera_rate - 1.0) < 0.1):
        rate_hz = camera_rate
    else:
        rate_hz = (len(times) - 1) / (times[-1] - times[0]) if period > 0 else 30.0
    rate = Fraction(round(rate_hz * 1000), 1000).limit_denominator(1001)
    out = out or run_dir / "onboard.mp4"
    count = 0
    with av.open(str(out), "w") as container:
        stream = None
        last_pts = -1
        for image in read_images(path, camera):
            frame = cv2.imdecode(np.frombuffer(image.jpeg, np.uint8), cv2.IMREAD_COLOR)
            if frame is None:
                continue
            if stream is None:
                stream = container.add_stream("libx264", rate=rate)
                stream.height, stream.width = frame.shape[:2]
                stream.pix_fmt = "yuv420p"
                stream.options = {"crf": str(crf), "preset": "veryfast"}
                stream.codec_context.time_base = 1 / rate
            drawn = draw_overlay(frame, source.overlay_at(image.time_s))
            video_frame = av.VideoFrame.from_ndarray(drawn, format="bgr24")
            # timestamps follow capture times: a dropped frame leaves a gap, not a speed-up
            pts = max(last_pts + 1, round((image.time_s - times[0]) * rate))
            video_frame.pts = last_pts = pts
            container.mux(stream.encode(video_frame))
            count += 1
        if stream is not None:
            container.mux(stream.encode(None))
    return out, count
