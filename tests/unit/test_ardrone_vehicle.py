"""The AR.Drone as the configuration builds it (driver: ardrone): its family's overlay (the
drone's cameras and ceiling), its address checked before anything opens (the protocol has no
authentication: a network address needs --insecure), calibrations applied or warned about."""

from __future__ import annotations

import dataclasses

import pytest

from autopilot.config import ConfigError
from autopilot.mission import load_mission
from autopilot.run import make_vehicle
from autopilot.vehicle_kinds import DRIVER_KINDS
from drivers.ardrone.driver import ArdroneDriver
from drivers.calibration import write_calibration


def test_the_overlay_makes_it_an_ardrone() -> None:
    plan = load_mission("follow_ball", ["driver=ardrone"])
    assert plan.config.link.connect == "ardrone://192.168.1.1"
    assert plan.config.vehicle.max_altitude_m == 3.0
    warnings = []
    vehicle, seed = make_vehicle(plan, connect="ardrone://127.0.0.1", warn=warnings.append)
    assert isinstance(vehicle, ArdroneDriver)
    assert seed is None
    front = vehicle.cameras["front"].intrinsics
    assert (front.width_px, front.height_px) == (640, 360)
    assert vehicle.cameras["down"].intrinsics.width_px == 320
    assert any("front: uncalibrated" in w for w in warnings)


def test_a_calibration_replaces_the_nominal_intrinsics(tmp_path) -> None:
    plan = load_mission("follow_ball", ["driver=ardrone"])
    nominal = make_vehicle(plan, connect="ardrone://127.0.0.1")[0].cameras["front"].intrinsics
    calibrated = dataclasses.replace(nominal, fx=nominal.fx * 1.05,
                                     distortion=(-0.1, 0.01, 0.0, 0.0, 0.0))
    file = tmp_path / "front.yaml"
    write_calibration(file, calibrated)
    warnings = []
    vehicle, _ = make_vehicle(plan, connect="ardrone://127.0.0.1", calibration=str(file),
                              warn=warnings.append)
    assert vehicle.cameras["front"].intrinsics.fx == pytest.approx(calibrated.fx)
    assert not any("front" in w for w in warnings)
    with pytest.raises(ConfigError, match="--calibration"):
        make_vehicle(plan, connect="ardrone://127.0.0.1", calibration=str(tmp_path / "no.yaml"))


def test_the_address_is_checked_before_anything_opens() -> None:
    kind = DRIVER_KINDS["ardrone"]
    kind.check_connect("--connect", "ardrone://127.0.0.1:5654", None, False)
    with pytest.raises(ConfigError, match="no authentication"):
        kind.check_connect("--connect", "ardrone://192.168.1.1", None, False)
    kind.check_connect("--connect", "ardrone://192.168.1.1", None, True)  # --insecure
    with pytest.raises(ConfigError, match="expected ardrone://HOST"):
        kind.check_connect("--connect", "udpin://127.0.0.1:14540", None, False)
    plan = load_mission("follow_ball", ["driver=ardrone"])
    with pytest.raises(ConfigError, match="--connect"):
        make_vehicle(plan, connect="ardrone//nope")
