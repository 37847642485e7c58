"""goto, orbit and survey (seed 004's offboard missions) through the runtime on the lockstep
clock: the trajectories are tracked within 10 cm, the photos are where and what the plan said,
and photogrammetry-style readers (exifread, which OpenDroneMap uses) read their EXIF."""

import asyncio
import json
import math

import exifread
import pytest

from autopilot.flightlog import records as ch
from autopilot.flightlog.log import read_log
from autopilot.mission import load_mission
from autopilot.report.html import write_report
from autopilot.run import fly


def _degrees(tag, ref) -> float:
    d, m, s = (float(v.num) / float(v.den) for v in tag.values)
    value = d + m / 60.0 + s / 3600.0
    return -value if str(ref) in ("S", "W") else value


def _read_exif(path) -> dict:
    with open(path, "rb") as f:
        tags = exifread.process_file(f, details=False)
    alt = tags["GPS GPSAltitude"].values[0]
    return {"lat": _degrees(tags["GPS GPSLatitude"], tags["GPS GPSLatitudeRef"]),
            "lon": _degrees(tags["GPS GPSLongitude"], tags["GPS GPSLongitudeRef"]),
            "alt": float(alt.num) / float(alt.den), "make": str(tags["Image Make"]),
            "model": str(tags["Image Model"]),
            "focal_mm": float(tags["EXIF FocalLength"].values[0].num)
            / float(tags["EXIF FocalLength"].values[0].den),
            "time": str(tags["EXIF DateTimeOriginal"])}


def _check_photos(out, summary, count: int) -> list[dict]:
    photos = sorted((out / "photos").glob("photo_*.jpg"))
    assert len(photos) == count
    records = read_log(out / "flight.mcap")[ch.PHOTOS]
    assert len(records) == count
    origin_lat, origin_lon = 47.397742, 8.545594  # config.yaml's sim.global_origin
    for path, rec in zip(photos, records, strict=True):
        exif = _read_exif(path)
        assert exif["make"] == "autopilot"
        assert exif["focal_mm"] > 0
        assert exif["time"]
        assert exif["lat"] == pytest.approx(rec["lat_deg"], abs=1e-7)
        assert exif["lon"] == pytest.approx(rec["lon_deg"], abs=1e-7)
        assert exif["alt"] == pytest.approx(rec["alt_amsl_m"], abs=0.01)
        # and the position is where the vehicle was (north/east from the origin, in metres)
        north = (exif["lat"] - origin_lat) * math.pi / 180 * 6_371_000
        east = (exif["lon"] - origin_lon) * math.pi / 180 * 6_371_000 * math.cos(
            math.radians(origin_lat))
        assert north == pytest.approx(rec["position_ned_m"][0], abs=0.05)
        assert east == pytest.approx(rec["position_ned_m"][1], abs=0.05)
        with open(path, "rb") as f:
            assert b"drone-dji:GimbalPitchDegree" in f.read()  # the attitude, in XMP
    geo = json.loads((out / "photos" / "photos.geojson").read_text())
    kinds = [f["properties"]["kind"] for f in geo["features"]]
    assert kinds.count("photo") == count
    assert kinds.count("footprint") == count
    return records


def test_orbit_tracks_the_circle_and_takes_every_photo_facing_the_centre(tmp_path):
    plan = load_mission("orbit")
    summary = asyncio.run(fly(plan, tmp_path))
    assert summary["status"] == "completed", summary["reason"]
    orbit = summary["metrics"]["orbit"]
    # the tracker's own accuracy: against the vehicle's navigation, whose frame the circle is
    # given in; against truth the GNSS navigation's decimetres come on top (and say so)
    assert orbit["rms_cross_track_nav_m"] <= 0.10
    assert orbit["max_cross_track_nav_m"] <= 0.25
    assert orbit["radius_rms_error_nav_m"] <= 0.10
    assert orbit["rms_navigation_error_m"] > 0.1
    assert orbit["rms_cross_track_m"] <= orbit["rms_navigation_error_m"] + 0.10
    assert orbit["along_track_speed_mean_m_s"] == pytest.approx(2.0, abs=0.1)
    assert orbit["photos"] == orbit["images_planned"] == 8
    assert orbit["photos_with_gps"] == 8
    # facing the centre: it is in every photo (the down camera, from 10 m at 3 m)
    assert orbit["centre_in_frame"] == 8
    _check_photos(tmp_path, summary, 8)
    assert summary["mission_status"] == 9  # landing completed
    statuses = [r["code"] for r in read_log(tmp_path / "flight.mcap")[ch.MISSION_STATUS]]
    assert statuses == [1, 2, 6, 7, 8, 9]
    page = write_report(tmp_path).read_text()
    assert "Planned path and flown track" in page
    assert "Mission status" in page
    assert "class='none'" not in page


def test_survey_of_a_concave_polygon_covers_it(tmp_path):
    u_shape = "[[0,0],[20,0],[20,20],[14,20],[14,7],[6,7],[6,20],[0,20]]"
    plan = load_mission("survey", [f"steps.1.survey.polygon_m={u_shape}",
                                   "steps.1.survey.altitude_m=8",
                                   "steps.1.survey.spacing_m=5",
                                   "steps.1.survey.photo_spacing_m=5"])
    summary = asyncio.run(fly(plan, tmp_path))
    assert summary["status"] == "completed", summary["reason"]
    survey = summary["metrics"]["survey"]
    assert survey["coverage"] >= 0.99
    assert survey["rms_cross_track_nav_m"] <= 0.10  # (truth: the navigation's error on top)
    assert survey["rms_cross_track_m"] <= survey["rms_navigation_error_m"] + 0.10
    assert survey["photos"] == survey["photos_planned"] >= 12
    assert survey["side_overlap_mean"] > 0.3
    assert survey["forward_overlap_mean"] > 0.3
    _check_photos(tmp_path, summary, survey["photos"])


def test_goto_in_the_home_frame_and_by_latitude_longitude(tmp_path):
    mission = tmp_path / "goto.yaml"
    mission.write_text("""
name: goto
steps:
  - takeoff: {altitude_m: 2.0}
  - goto: {position_m: [6.0, -3.0, 4.0], frame: home, speed_m_s: 3.0, yaw_deg: 90}
  - goto: {latlon: [47.397742, 8.545594, 3.0], speed_m_s: 2.0}
  - land: {}
scenario: {ball: null}
""")
    summary = asyncio.run(fly(load_mission(str(mission)), tmp_path / "run"))
    assert summary["status"] == "completed", summary["reason"]
    steps = {s["index"]: s for s in summary["metrics"]["steps"]}
    # where the navigation put it (the goal is in its frame); truth: the GNSS error on top
    assert steps[1]["goto"]["final_error_nav_m"] <= 0.3
    assert steps[1]["goto"]["rms_cross_track_nav_m"] <= 0.10
    assert steps[2]["goto"]["final_error_nav_m"] <= 0.3
    for k in (1, 2):
        goto = steps[k]["goto"]
        assert goto["final_error_m"] <= goto["final_error_nav_m"] + 3 * 0.5  # 3σ of GNSS
    log = read_log(tmp_path / "run" / "flight.mcap")
    first = next(r for r in log[ch.PLANNED_PATH] if r["step_index"] == 1)
    # home is where it armed, as its navigation had it (on GNSS decimetres off the origin;
    # its height resting on its legs): the goal is 6 m north, 3 m west and 4 m up from there
    home = next(r["position_ned_m"] for r in log[ch.VEHICLE_STATE] if r["armed"])
    assert first["points_ned_m"][-1] == pytest.approx(
        [home[0] + 6.0, home[1] - 3.0, -4.0], abs=0.12)
    second = next(r for r in log[ch.PLANNED_PATH] if r["step_index"] == 2)
    assert second["points_ned_m"][-1] == pytest.approx([0.0, 0.0, -3.0], abs=0.12)
    statuses = [r["code"] for r in log[ch.MISSION_STATUS]]
    assert statuses[:6] == [1, 2, 4, 5, 4, 5]


def test_a_goto_beyond_the_geofence_is_refused_when_it_starts_and_lands(tmp_path):
    """failsafe.geofence: a goto 30 m out with a fence at 12 m is refused when the step starts
    (where it goes is known then), naming the limit; nothing is flown towards it; the
    mission's fallback lands."""
    mission = tmp_path / "far.yaml"
    mission.write_text("name: far\ndescription: too far\nsteps:\n"
                       "  - takeoff: {altitude_m: 3.0}\n"
                       "  - goto: {position_m: [30, 0, 3], speed_m_s: 3}\n"
                       "  - land: {}\nfallback: land\n")
    plan = load_mission(str(mission), ["failsafe.geofence.max_distance_m=12"])
    summary = asyncio.run(fly(plan, tmp_path / "run"))
    assert summary["status"] == "failed"
    assert "max_distance_m (12)" in summary["reason"]
    records = read_log(tmp_path / "run" / "flight.mcap")
    truth = records[ch.GROUND_TRUTH]
    assert max(math.hypot(*r["vehicle_position_ned_m"][:2]) for r in truth) < 1.0
    assert truth[-1]["vehicle_position_ned_m"][2] > -0.3  # landed
    assert ch.PLANNED_PATH not in records or not records[ch.PLANNED_PATH]


def test_following_out_of_the_geofence_is_stopped_at_it_and_lands(tmp_path):
    """The fence on every setpoint: following the ball with the fence 1 m from home, no
    position target is sent past it, a velocity carrying the vehicle out stops it; the mission's
    fallback holds and lands inside a margin."""
    plan = load_mission("follow_ball", ["failsafe.geofence.max_distance_m=1.0"])
    summary = asyncio.run(fly(plan, tmp_path / "run"))
    assert summary["status"] == "aborted", summary["reason"]
    assert "geofence" in summary["reason"]
    records = read_log(tmp_path / "run" / "flight.mcap")
    truth = records[ch.GROUND_TRUTH]
    furthest = max(math.hypot(*r["vehicle_position_ned_m"][:2]) for r in truth)
    assert furthest < 1.0 + 1.0  # braking at the fence
    assert truth[-1]["vehicle_position_ned_m"][2] > -0.3  # landed
