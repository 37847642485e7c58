"""The ``land_on_rover`` step kind: precision landing on a moving rover's deck (seed 004).

Its behaviour is :class:`~autopilot.behaviors.land_on_rover.LandOnRover`, its pipeline the deck
pipeline (:mod:`autopilot.perception.deck_pipeline`: the relative-state filter fusing UWB, the
deck's tag, the rangefinder and the rover's reports; ``use_uwb`` / ``use_marker`` choose).

Its metrics (simulator ground truth, scoring only):

``landing``
    ``on_deck`` — the vehicle came to rest on the deck (standing on it, inside its edges,
    carried at the rover's speed); ``error_m`` — at touchdown (first contact), the body's
    horizontal distance from the deck's centre (``error_deck_m``: along and across the rover);
    ``rest_error_m`` — the same where it came to rest; ``relative_speed_m_s`` /
    ``relative_horizontal_speed_m_s`` — against the deck over the last 0.3 s before contact;
    ``time_to_land_s``; ``retries`` (aborts and climbs); ``landed`` (the step succeeded).
``relative``
    The relative estimate the behaviour flew on (``/control/target``: the deck in the drone's
    own frame, minus the drone's own position estimate) against the true relative position:
    horizontal and vertical RMS, p95 and worst; ``within_2sigma`` (both horizontal axes within
    2σ); the share of control ticks without a usable estimate; and each source's availability
    (the share of the step with an update from it within the last 0.5 s).
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Mapping, Sequence

import numpy as np

from autopilot.behaviors.land_on_rover import (
    LandOnRover,
    LandOnRoverParams,
    LandOnRoverSettings,
    Seed004LandingSettings,
    Seed004LandOnRover,
)
from autopilot.flightlog import records as ch
from autopilot.flightlog.metrics import Estimates, phase_entries
from autopilot.flightlog.truth import extend_floats, truth_table
from autopilot.perception.deck_pipeline import ROVER_BODY, deck_spec
from autopilot.report.panels import NoData, register_panel, shade_steps
from autopilot.steps.follow_ball import camera_of
from autopilot.steps.registry import LANDING_REPLAY_KEYS, Figure, StepContext, StepKind, register
from drivers.geometry import yaw_from_quat as _yaw_of

#: resting: within this of the height the vehicle finally rests at over the deck
_REST_BAND_M = 0.015
SOURCES = ("uwb", "tag", "range", "rover")


def _behavior(params: LandOnRoverParams, ctx: StepContext) -> LandOnRover:
    config = ctx.config
    if params.use_marker:
        camera_of(ctx, config.rover.camera, "rover.camera")
    settings = LandOnRoverSettings(tuple(config.rover.deck_size_m), config.rover.deck_height_m)
    if params.strategy == "seed004":
        return Seed004LandOnRover(params, settings, Seed004LandingSettings(
            **config.control.seed004_landing.model_dump()))
    return LandOnRover(params, settings)


def _spec(params: LandOnRoverParams, config):
    return (deck_spec(config, params.use_uwb, params.use_marker, params.strategy),)


def _check(params: LandOnRoverParams, config) -> None:
    if params.commit_height_m >= params.approach_height_m:
        raise ValueError(f"commit_height_m ({params.commit_height_m}) must be below "
                         f"approach_height_m ({params.approach_height_m})")
    if params.touchdown_height_m >= params.commit_height_m:
        raise ValueError(f"touchdown_height_m ({params.touchdown_height_m}) must be below "
                         f"commit_height_m ({params.commit_height_m})")
    if params.use_marker and config.rover.camera not in config.vehicle.cameras:
        raise ValueError(f"use_marker: the deck's tag is read by rover.camera "
                         f"{config.rover.camera!r}, which the vehicle does not have")


def _interp(t: np.ndarray, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, times, values[:, i]) for i in range(values.shape[1])],
                    axis=1)


def landing_metrics(log: Mapping[str, Sequence[Mapping]], intervals: list[tuple[float, float]],
                    step: Mapping) -> dict:
    pipelines = step.get("pipelines") or []
    if not pipelines or not intervals:
        return {}
    p = pipelines[0]
    body = p.get("truth_body") or ROVER_BODY
    params = LandOnRoverParams(**step["params"])
    start, end = intervals[0][0], intervals[-1][1]
    succeeded = any(e.get("kind") == "step_succeeded" and e.get("step_index") == step["index"]
                    for e in log.get(ch.MISSION_EVENTS, []))
    until = end + 2.0 if succeeded else math.inf
    track = truth_table(log).body(body)
    truth = track.window((track.t >= start) & (track.t <= until))
    if len(truth) < 2:
        return {}
    config = _config(log)
    deck_l, deck_w = config.get("deck_size_m", (1.0, 0.8))
    t = truth.t
    drone_v = truth.vehicle_v
    deck_v = truth.v
    yaw = np.array([_yaw_of(q) for q in truth.q])
    rel = truth.vehicle_p - truth.p
    rel_v = drone_v - deck_v
    # in the rover's axes (along, across)
    c, s_ = np.cos(yaw), np.sin(yaw)
    along = c * rel[:, 0] + s_ * rel[:, 1]
    across = -s_ * rel[:, 0] + c * rel[:, 1]
    height = -rel[:, 2]
    retries = phase_entries(log.get(ch.SETPOINTS, []), step["name"], start, end, "aborting")
    landing: dict = {
        "landed": succeeded, "on_deck": False, "error_m": None, "error_deck_m": None,
        "rest_error_m": None, "relative_speed_m_s": None,
        "relative_horizontal_speed_m_s": None, "time_to_land_s": None, "retries": retries,
        "rover_speed_m_s": float(np.hypot(*deck_v[-1][:2])),
        "use_uwb": params.use_uwb, "use_marker": params.use_marker}
    rest_h = float(height[-1])
    still = float(np.linalg.norm(rel_v[-1])) < 0.1
    inside = abs(float(along[-1])) <= deck_l / 2.0 and abs(float(across[-1])) <= deck_w / 2.0
    on_deck = still and inside and 0.0 < rest_h < 0.3
    if on_deck:
        k = len(height) - 1
        while k > 0 and height[k - 1] <= rest_h + _REST_BAND_M:
            k -= 1
        before = (t >= t[k] - 0.3) & (t <= t[k])
        landing.update({
            "on_deck": True,
            "error_m": float(math.hypot(along[k], across[k])),
            "error_deck_m": [float(along[k]), float(across[k])],
            "rest_error_m": float(math.hypot(along[-1], across[-1])),
            "relative_speed_m_s": float(np.max(np.linalg.norm(rel_v[before], axis=1))),
            "relative_horizontal_speed_m_s": float(np.max(np.linalg.norm(
                rel_v[before][:, :2], axis=1))),
            "time_to_land_s": float(t[k] - start)})
    out = {"landing": landing}
    rel_metrics = relative_metrics(log, intervals, p["name"], t, rel)
    if rel_metrics:
        out["relative"] = rel_metrics
    return out


def _config(log: Mapping[str, Sequence[Mapping]]) -> dict:
    plans = log.get(ch.MISSION_PLAN, [])
    if not plans:
        return {}
    return (plans[-1].get("config") or {}).get("rover") or {}


def _own_positions(log: Mapping[str, Sequence[Mapping]]) -> tuple[np.ndarray, np.ndarray]:
    """The drone's own position estimate (its telemetry): times and positions."""
    t, p = array("d"), array("d")
    for r in log.get(ch.VEHICLE_STATE, []):
        t.append(r["time_s"])
        extend_floats(p, r["position_ned_m"], 3)
    return np.array(t), np.array(p).reshape(-1, 3)


def relative_metrics(log: Mapping[str, Sequence[Mapping]], intervals: list[tuple[float, float]],
                     pipeline: str, truth_t: np.ndarray, truth_rel: np.ndarray) -> dict:
    """The relative estimate flown on (see the module's notes) against the truth."""
    start, end = intervals[0][0], intervals[-1][1]
    ticks = 0
    usable = Estimates()
    for r in log.get(ch.CONTROL_TARGET, []):
        if r.get("pipeline") == pipeline and any(a <= r["time_s"] <= b for a, b in intervals):
            ticks += 1
            if r.get("present") and not r.get("stale"):
                usable.add(r)
    if not ticks or len(log.get(ch.VEHICLE_STATE, [])) < 2:
        return {}
    out: dict = {"ticks": ticks, "lost_share": 1.0 - len(usable) / ticks}
    if len(usable):
        st, sp = _own_positions(log)
        tt, deck, _, std = usable.columns()
        covered = (tt >= truth_t[0]) & (tt <= truth_t[-1]) & (tt >= st[0])
        tt, deck, std = tt[covered], deck[covered], std[covered]
        if len(tt):
            # the drone's own estimate at each tick (its telemetry carried to the tick)
            own = _interp(tt, st, sp)
            est = own - deck
            true = _interp(tt, truth_t, truth_rel)
            err = est - true
            horiz = np.hypot(err[:, 0], err[:, 1])
            within = (np.abs(err[:, 0]) <= 2.0 * std[:, 0]) & \
                (np.abs(err[:, 1]) <= 2.0 * std[:, 1])
            out.update({
                "rms_horizontal_error_m": float(np.sqrt(np.mean(horiz ** 2))),
                "p95_horizontal_error_m": float(np.percentile(horiz, 95)),
                "max_horizontal_error_m": float(np.max(horiz)),
                "rms_vertical_error_m": float(np.sqrt(np.mean(err[:, 2] ** 2))),
                "within_2sigma": float(np.mean(within)),
                "final_horizontal_error_m": float(horiz[-1])})
    measured: dict[str, array] = {source: array("d") for source in SOURCES}
    for r in log.get(ch.RELATIVE_ESTIMATES, []):
        if r.get("pipeline") == pipeline and r.get("accepted") and r.get("source") in measured:
            measured[r["source"]].append(r["measurement_time_s"])
    grid = np.arange(start, end, 0.1)
    availability = {}
    for source in SOURCES:
        times = np.sort(np.array(measured[source]))
        if not len(times) or not len(grid):
            availability[source] = 0.0
            continue
        idx = np.searchsorted(times, grid, side="right") - 1
        fresh = (idx >= 0) & (grid - times[np.maximum(idx, 0)] <= 0.5)
        availability[source] = float(np.mean(fresh))
    out["availability"] = availability
    out["updates"] = {source: len(measured[source]) for source in SOURCES}
    return out


def relative_tracks(log: Mapping[str, Sequence[Mapping]], body: str = ROVER_BODY) -> dict | None:
    """What the report's rover panel draws: the drone relative to the deck in the rover's axes
    (along, across, height above the deck) — truth, and the estimate flown on — and the
    relative filter's updates per source with their horizontal error against truth."""
    truth = truth_table(log).body(body)
    if len(truth) < 2:
        return None
    t = truth.t
    rel = truth.vehicle_p - truth.p
    yaw = np.array([_yaw_of(q) for q in truth.q])

    def axes(r: np.ndarray, psi: np.ndarray) -> np.ndarray:
        c, s_ = np.cos(psi), np.sin(psi)
        return np.column_stack((c * r[:, 0] + s_ * r[:, 1], -s_ * r[:, 0] + c * r[:, 1],
                                -r[:, 2]))

    out: dict = {"deck_size_m": tuple(_config(log).get("deck_size_m", (1.0, 0.8))),
                 "truth": axes(rel, yaw)}
    ticks = Estimates()
    for r in log.get(ch.CONTROL_TARGET, []):
        if r.get("present") and str(r.get("pipeline", "")).startswith("deck"):
            ticks.add(r)
    flown = np.zeros((0, 3))
    if len(ticks) and len(log.get(ch.VEHICLE_STATE, [])) >= 2:
        st, sp = _own_positions(log)
        tt, deck, _, _ = ticks.columns()
        keep = (tt >= max(st[0], t[0])) & (tt <= t[-1])
        if keep.any():
            tt, deck = tt[keep], deck[keep]
            flown = axes(_interp(tt, st, sp) - deck, np.interp(tt, t, np.unwrap(yaw)))
    out["flown"] = flown
    accepted = {source: (array("d"), array("d")) for source in SOURCES}  # times, positions
    rejected_at = {source: array("d") for source in SOURCES}
    sig_t, two_sigma = array("d"), array("d")
    for r in log.get(ch.RELATIVE_ESTIMATES, []):
        if not t[0] <= r["time_s"] <= t[-1]:
            continue
        source = r.get("source")
        if r.get("accepted"):
            sig_t.append(r["time_s"])
            two_sigma.append(2.0 * max(r["position_std_m"][0], r["position_std_m"][1]))
            if source in accepted:
                accepted[source][0].append(r["time_s"])
                extend_floats(accepted[source][1], r["relative_position_m"], 3)
        elif source in rejected_at:
            rejected_at[source].append(r["measurement_time_s"])
    updates = {}
    for source in SOURCES:
        times = np.array(accepted[source][0])
        if len(times):
            est = np.array(accepted[source][1]).reshape(-1, 3)
            true = _interp(times, t, rel)
            error = np.hypot(est[:, 0] - true[:, 0], est[:, 1] - true[:, 1])
        else:
            error = np.zeros(0)
        updates[source] = {"t": times, "error_m": np.maximum(error, 1e-4)}
    out["updates"] = updates
    out["rejected"] = {source: np.array(rejected_at[source]) for source in SOURCES}
    out["sigma_t"] = np.array(sig_t)
    out["two_sigma_m"] = np.array(two_sigma)
    return out


def draw_rover_panel(fig, records, phases, target) -> None:
    """Landing on the rover: the drone relative to the deck (truth, and the estimate the
    controller flew on) from above and from the side in the rover's axes; the relative
    estimate's error per source at each update, with its 2σ; when each source updated."""
    tr = relative_tracks(records)
    if tr is None:
        raise NoData("no rover in this log")
    fig.set_size_inches(10, 7.5)
    (top, side), (err, avail) = fig.subplots(2, 2)
    length, width = tr["deck_size_m"]
    top.add_patch(__import__("matplotlib.patches", fromlist=["Rectangle"]).Rectangle(
        (-width / 2, -length / 2), width, length, fill=False, color="#888", lw=1))
    top.plot(tr["truth"][:, 1], tr["truth"][:, 0], "-", lw=1, label="truth")
    if len(tr["flown"]):
        top.plot(tr["flown"][:, 1], tr["flown"][:, 0], ":", lw=1, label="estimate flown on")
    top.set(xlabel="across the rover (m, right +)", ylabel="along the rover (m, front +)",
            title="relative track from above (deck outlined)", aspect="equal")
    near = np.abs(tr["truth"][:, 2]) < 4.0
    if near.any():
        span = max(1.0, float(np.abs(tr["truth"][near, :2]).max()) * 1.1)
        top.set(xlim=(-span, span), ylim=(-span, span))
    top.legend(fontsize=7)
    side.axhspan(-0.02, 0.0, color="#888")
    side.plot(tr["truth"][:, 0], tr["truth"][:, 2], "-", lw=1, label="truth")
    if len(tr["flown"]):
        side.plot(tr["flown"][:, 0], tr["flown"][:, 2], ":", lw=1, label="estimate flown on")
    side.set(xlabel="along the rover (m)", ylabel="height above the deck (m)",
             title="from the side")
    side.legend(fontsize=7)
    colours = {"uwb": "#1f77b4", "tag": "#d62728", "range": "#2ca02c", "rover": "#9467bd"}
    for source, rows in tr["updates"].items():
        if len(rows["t"]):
            err.plot(rows["t"], rows["error_m"] * 100.0, ".", ms=2, color=colours[source],
                     label=f"after {source}")
    if len(tr["sigma_t"]):
        err.plot(tr["sigma_t"], tr["two_sigma_m"] * 100.0, "-", lw=0.8, color="#555",
                 label="2σ (horizontal)")
    err.set(xlabel="time (s)", ylabel="horizontal error (cm)", yscale="log",
            title="relative estimate against truth, per source")
    err.legend(fontsize=6, ncol=2)
    shade_steps(err, phases)
    for row, source in enumerate(("uwb", "tag", "range", "rover")):
        rows = tr["updates"][source]
        if len(rows["t"]):
            avail.plot(rows["t"], np.full(len(rows["t"]), row), "|", ms=8,
                       color=colours[source])
        rej = tr["rejected"][source]
        if len(rej):
            avail.plot(rej, np.full(len(rej), row - 0.3), "|", ms=4, color="#999")
    avail.set(yticks=range(4), yticklabels=["UWB", "tag", "rangefinder", "rover report"],
              xlabel="time (s)", title="sensor updates (grey: rejected by the gate)",
              ylim=(-0.8, 3.5))
    shade_steps(avail, phases)
    fig.tight_layout()


register_panel("rover", "Landing on the rover", draw_rover_panel, order=9)

register(StepKind(
    "land_on_rover", LandOnRoverParams, _behavior, pipelines=_spec, metrics=landing_metrics,
    summary=((Figure("landing", "on_deck", "on the deck"),
              Figure("landing", "error_m", "touchdown error", "m"),
              Figure("landing", "relative_horizontal_speed_m_s", "relative speed at touchdown",
                     "m/s"),
              Figure("landing", "time_to_land_s", "time to land", "s"),
              Figure("landing", "retries", "retries")),
             (Figure("relative", "rms_horizontal_error_m",
                     "rover estimate flown on: horizontal error RMS", "m"),
              Figure("relative", "within_2sigma", "within its 2σ", "%"),
              Figure("relative", "lost_share", "rover lost (no estimate)", "%",
                     "of the step"))),
    report=("trajectory", "rover", "latency"), check=_check,
    needs=lambda params, config: ("rover_link",),
    description="land on a moving rover's deck: UWB, its tag and its reports fused "
                "(seed 004)",
    replay={"landing": LANDING_REPLAY_KEYS, "relative": None},
    status=(8, 9)))
