"""ArduCopter's parameter table (drivers/sim/flight/arducopter_params.py) against the values
ArduPilot's sources give (docs/reference/ardupilot-mavlink.md): names a ground station looks
for, their units and defaults, the SI values the flight code would fly on."""

import pytest

from drivers.sim.flight.arducopter_params import (
    ARDUCOPTER_PARAMS,
    SPECS,
    STREAM_GROUPS,
    si_limits,
)
from drivers.sim.flight.params import ParamError, ParamType


def test_every_default_is_valid_names_fit_mavlink_and_are_unique():
    names = [spec.name for spec in ARDUCOPTER_PARAMS]
    assert len(names) == len(set(names))
    for spec in ARDUCOPTER_PARAMS:
        assert len(spec.name) <= 16, spec.name  # PARAM_VALUE's param_id
        assert spec.check(spec.default) == spec.default, spec.name


@pytest.mark.parametrize(("name", "default", "unit"), [
    ("WPNAV_SPEED", 1000, "cm/s"), ("RTL_ALT", 1500, "cm"), ("LAND_SPEED", 50, "cm/s"),
    ("GUID_TIMEOUT", 3.0, "s"), ("RTL_LOIT_TIME", 5000, "ms"), ("ANGLE_MAX", 3000, "cdeg"),
    ("DISARM_DELAY", 10, "s"), ("FS_GCS_ENABLE", 0, ""), ("FS_GCS_TIMEOUT", 5.0, "s"),
    ("FENCE_RADIUS", 150.0, "m"), ("PLND_STRICT", 1, ""), ("PLND_RET_MAX", 4, ""),
    ("SYSID_MYGCS", 255, ""), ("SERIAL0_PROTOCOL", 2, ""), ("BATT_MONITOR", 4, ""),
])
def test_arducopters_defaults_and_units(name, default, unit):
    assert SPECS[name].default == default
    assert SPECS[name].unit == unit


def test_the_stream_rates_start_at_zero_on_every_mavlink_port():
    for port in (0, 1, 2):
        for group in STREAM_GROUPS:
            spec = SPECS[f"SR{port}_{group}"]
            assert spec.default == 0
            assert spec.type is ParamType.INT16


def test_integer_types_refuse_fractions_and_enums_their_holes():
    assert SPECS["DISARM_DELAY"].type is ParamType.INT8
    with pytest.raises(ParamError, match="not an integer"):
        SPECS["DISARM_DELAY"].check(2.5)
    with pytest.raises(ParamError, match="not one of"):
        SPECS["FS_GCS_ENABLE"].check(2)  # removed in 4.x (see FS_OPTIONS)
    with pytest.raises(ParamError, match="out of range"):
        SPECS["GUID_TIMEOUT"].check(9.0)


def test_si_limits_convert_units_and_apply_arducopters_fallbacks():
    si = si_limits({})
    assert si.wp_speed_m_s == 10.0
    assert si.rtl_altitude_m == 15.0
    assert si.rtl_loiter_s == 5.0
    assert si.rtl_speed_m_s == 10.0  # RTL_SPEED 0: WPNAV_SPEED
    assert si.land_speed_m_s == 0.5
    assert si.land_speed_high_m_s == 1.5  # LAND_SPEED_HIGH 0: WPNAV_SPEED_DN
    assert si.max_tilt_deg == 30.0
    si = si_limits({"RTL_SPEED": 300, "RTL_ALT": 10, "GUID_TIMEOUT": 0.1})
    assert si.rtl_speed_m_s == 3.0
    assert si.rtl_altitude_m == 0.3  # at least 30 cm
    assert si.guided_timeout_s == 0.1
