"""The simulated vehicle's PX4 parameters without an event loop: what a value is stored as,
what is refused (and that a refusal changes nothing), listeners, the index order and the
configuration's overrides."""

import math

import pytest

from drivers.sim.flight.params import (
    PX4_PARAMS,
    SPECS,
    ParamError,
    Parameters,
    ParamSpec,
    ParamType,
    config_defaults,
    validate_overrides,
)


def test_every_default_is_valid_and_typed():
    params = Parameters()
    assert len(params) == len(PX4_PARAMS) == len(SPECS)
    for spec in PX4_PARAMS:
        value = params[spec.name]
        assert type(value) is (float if spec.type is ParamType.FLOAT else int), spec.name
        assert spec.min <= value <= spec.max


def test_float_parameters_store_floats():
    spec = SPECS["MPC_XY_CRUISE"]
    assert spec.check(7) == 7.0
    assert isinstance(spec.check(7), float)
    assert spec.check(3.0) == 3.0  # the range is inclusive
    assert spec.check(20.0) == 20.0


def test_integer_parameters_store_ints():
    spec = SPECS["GF_ACTION"]
    assert spec.check(3.0) == 3
    assert isinstance(spec.check(3.0), int)


@pytest.mark.parametrize(("name", "value", "reason"), [
    ("MPC_XY_CRUISE", 2.9, r"out of range \[3, 20\]"),
    ("MPC_XY_CRUISE", 20.5, "out of range"),
    ("MPC_XY_CRUISE", math.nan, "not a number"),
    ("MPC_XY_CRUISE", math.inf, "not a number"),
    ("GF_ACTION", 2.5, "not an integer"),
    ("GF_ACTION", 6, "out of range"),
    ("GF_ACTION", -1, "out of range"),
    ("RTL_CONE_ANG", 30, "not one of 0, 25, 45, 65, 80, 90"),
    ("NAV_DLL_ACT", 4, "not one of"),
])
def test_refused_values(name, value, reason):
    with pytest.raises(ParamError, match=reason) as info:
        SPECS[name].check(value)
    assert info.value.name == name


def test_a_refused_set_changes_nothing_and_tells_no_listener():
    params = Parameters()
    changes = []
    params.on_change(lambda name, value: changes.append((name, value)))
    before = params.snapshot()
    for name, value in [("MPC_XY_CRUISE", 50.0), ("GF_ACTION", 2.5), ("RTL_CONE_ANG", 30),
                        ("MPC_XY_CRUISE", math.nan)]:
        with pytest.raises(ParamError):
            params.set(name, value)
    with pytest.raises(ParamError, match="unknown parameter"):
        params.set("NOT_A_PARAM", 1.0)
    assert params.snapshot() == before
    assert changes == []


def test_listeners_hear_real_changes_only():
    params = Parameters()
    changes = []
    params.on_change(lambda name, value: changes.append((name, value)))
    assert params.set("RTL_RETURN_ALT", 25) == 25.0
    params.set("RTL_RETURN_ALT", 25.0)  # the same value again: no change
    params.set("GF_ACTION", 3.0)
    assert changes == [("RTL_RETURN_ALT", 25.0), ("GF_ACTION", 3)]
    assert params["GF_ACTION"] == 3


def test_a_value_that_is_no_number_is_a_param_error():
    with pytest.raises(ParamError):
        SPECS["MPC_XY_CRUISE"].check("fast")


def test_defaults_and_their_refusal():
    params = Parameters({"MPC_XY_CRUISE": 8.0, "GF_ACTION": 1})
    assert params["MPC_XY_CRUISE"] == 8.0
    assert params["GF_ACTION"] == 1
    with pytest.raises(ParamError):
        Parameters({"MPC_XY_CRUISE": 80.0})


def test_index_order_is_alphabetical_and_stable():
    params = Parameters()
    assert params.names == sorted(params.names)
    assert params.index("BAT_CRIT_THR") == params.names.index("BAT_CRIT_THR")
    assert "GF_ACTION" in params
    assert "NOT_A_PARAM" not in params


def test_a_custom_spec_list():
    specs = [ParamSpec("B_INT", ParamType.INT32, 1, 0, 3, values=(0, 1, 3)),
             ParamSpec("A_FLOAT", ParamType.FLOAT, 0.5, 0.0, 1.0)]
    params = Parameters(specs=specs)
    assert params.names == ["A_FLOAT", "B_INT"]
    with pytest.raises(ParamError, match="not one of 0, 1, 3"):
        params.set("B_INT", 2)
    with pytest.raises(ParamError, match="unknown parameter"):
        params.set("MPC_XY_CRUISE", 5.0)


def test_validate_overrides_lists_every_problem():
    problems = validate_overrides({"MPC_XY_CRUISE": 50.0, "NOPE": 1.0, "GF_ACTION": 2,
                                   "RTL_CONE_ANG": 30})
    assert len(problems) == 3
    assert any(p.startswith("MPC_XY_CRUISE: 50 is out of range") for p in problems)
    assert any(p.startswith("NOPE: unknown PX4 parameter") for p in problems)
    assert any(p.startswith("RTL_CONE_ANG: 30 is not one of") for p in problems)
    assert validate_overrides({"GF_ACTION": 2}) == []


def test_the_shipped_configuration_gives_valid_defaults(sim_config):
    defaults = config_defaults(sim_config)
    assert validate_overrides(defaults) == []
    params = Parameters(defaults)
    assert params["MPC_XY_CRUISE"] == sim_config.flight_stack.position.xy_cruise_m_s
    assert params["MIS_TAKEOFF_ALT"] == sim_config.flight_stack.commander.takeoff_altitude_m
