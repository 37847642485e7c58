"""Configuration loading and validation: every error names the file, the line and the key."""

import re

import pytest

from autopilot.cli import main
from autopilot.config import ConfigError, load_config
from autopilot.resources import default_config_path

SHIPPED = default_config_path().read_text()


def _write(tmp_path, text, name="config.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _line_of(text, needle):
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


def test_shipped_config_is_valid():
    cfg = load_config()
    assert cfg.driver == "sim"
    assert cfg.vehicle.cameras["front"].width_px == 640
    # one camera section: the simulator renders the vehicle's cameras
    assert cfg.sim.cameras["front"] == cfg.vehicle.cameras["front"]
    assert cfg.vehicle.cameras["down"].video == "udp://127.0.0.1:5601"


def test_cameras_moved_out_of_the_simulator_section():
    with pytest.raises(ConfigError, match=r"sim\.cameras: moved to vehicle\.cameras"):
        load_config(overrides=["sim.cameras.front.width_px=320"])


def test_unknown_key_names_file_line_and_path(tmp_path):
    text = SHIPPED.replace("    prop_diameter_m: 0.254\n",
                           "    prop_diameter_m: 0.254\n    prop_colour: red\n")
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, text))
    line = _line_of(text, "prop_colour")
    assert str(err.value) == f"config.yaml:{line}: sim.vehicle.prop_colour: unknown key"


def test_wrong_type(tmp_path):
    text = SHIPPED.replace("      width_px: 640\n", "      width_px: wide\n", 1)
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, text))
    line = _line_of(text, "width_px: wide")
    assert re.fullmatch(
        rf"config.yaml:{line}: vehicle.cameras.front.width_px: .*integer.*'wide'.*",
        str(err.value))


def test_out_of_range(tmp_path):
    text = SHIPPED.replace("      tilt_max_deg: 45.0", "      tilt_max_deg: 120.0")
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, text))
    line = _line_of(text, "tilt_max_deg")
    assert f"config.yaml:{line}: sim.flight_stack.position.tilt_max_deg: " in str(err.value)
    assert "less than 90" in str(err.value)


def test_missing_key_points_at_its_section(tmp_path):
    text = SHIPPED.replace("    capacity_mah: 5000\n", "")
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, text))
    sim = _line_of(text, "sim:")
    battery = next(i for i, line in enumerate(text.splitlines(), 1)
                   if i > sim and "battery:" in line)  # sim's, not failsafe's
    assert f"config.yaml:{battery}: sim.battery.capacity_mah: missing" in str(err.value)


def test_cross_field_rule(tmp_path):
    text = SHIPPED.replace("  physics_rate_hz: 500", "  physics_rate_hz: 600")
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, text))
    assert "physics_rate_hz (600) must be an integer multiple" in str(err.value)


def test_a_loop_stall_shorter_than_a_setpoints_life_is_refused():
    with pytest.raises(ConfigError, match=r"runtime: .*loop_stall_s \(0.1\) must be at least "
                                          r"setpoint_expiry_s"):
        load_config(overrides=["runtime.loop_stall_s=0.1", "runtime.setpoint_expiry_s=0.3"])


def test_duplicate_key(tmp_path):
    text = SHIPPED.replace("driver: sim", "driver: sim\ndriver: mavsdk", 1)
    with pytest.raises(ConfigError, match=r"config.yaml:\d+: driver: duplicate key"):
        load_config(_write(tmp_path, text))


def test_invalid_yaml_reports_line(tmp_path):
    text = SHIPPED.replace("  seed: 0", "  seed: [0", 1)
    with pytest.raises(ConfigError, match=r"config.yaml:\d+: .*invalid YAML"):
        load_config(_write(tmp_path, text))


def test_overrides_apply_and_are_validated():
    cfg = load_config(overrides=["sim.wind.gust_mps=2.5",
                                 "vehicle.cameras.down.enabled=false"])
    assert cfg.sim.wind.gust_mps == 2.5
    assert cfg.sim.cameras["down"].enabled is False
    with pytest.raises(ConfigError, match=r"--set: sim\.wind\.gust: unknown key"):
        load_config(overrides=["sim.wind.gust=1"])
    with pytest.raises(ConfigError, match=r"--set: sim.seed: .*greater than or equal to 0"):
        load_config(overrides=["sim.seed=-1"])
    with pytest.raises(ConfigError, match=r"expected dotted\.key=value"):
        load_config(overrides=["sim.seed"])


def test_validate_command_exit_codes(tmp_path, capsys):
    assert main(["validate", str(default_config_path())]) == 0
    bad = _write(tmp_path, SHIPPED.replace("driver: sim", "driver: ardupilot", 1), "bad.yaml")
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.yaml:" in err
    assert "driver:" in err


# ------------------------------------------------------------------------------------------
# Simulation profiles (sim.profile)
# ------------------------------------------------------------------------------------------


@pytest.fixture
def kind_overlay(tmp_path, monkeypatch):
    """An ``ideal`` overlay that changes two keys, standing in for the shipped one."""
    overlay = tmp_path / "ideal.yaml"
    overlay.write_text("sim:\n  rangefinder: {noise_m: 0.0001}\n"
                       "  estimator: {grade: rtk}\n")
    import autopilot.config.loader as config_loader

    monkeypatch.setattr(config_loader, "profile_path",
                        lambda name: overlay if name == "ideal" else None)
    return overlay


def test_a_profile_lays_its_overlay_under_what_the_user_sets(kind_overlay):
    base = load_config(overrides=["sim.profile=realistic"])
    ideal = load_config(overrides=["sim.profile=ideal"])
    assert ideal.sim.profile == "ideal"
    assert base.sim.profile == "realistic"
    assert ideal.sim.rangefinder.noise_m == 0.0001
    assert ideal.sim.estimator.grade == "rtk"
    # what the overlay does not name stays as config.yaml has it
    assert ideal.sim.rangefinder.max_m == base.sim.rangefinder.max_m
    # each dimension is still settable on its own, whatever the profile
    mixed = load_config(overrides=["sim.profile=ideal", "sim.rangefinder.noise_m=0.3"])
    assert mixed.sim.rangefinder.noise_m == 0.3
    assert mixed.sim.estimator.grade == "rtk"


def test_a_missions_profile_and_its_own_keys(kind_overlay, tmp_path):
    from autopilot.mission import load_mission

    mission = tmp_path / "m.yaml"
    mission.write_text("name: m\nsteps:\n  - takeoff: {altitude_m: 2}\n  - land: {}\n"
                       "config:\n  sim:\n    profile: ideal\n    rangefinder: {noise_m: 0.2}\n")
    plan = load_mission(str(mission))
    assert plan.config.sim.profile == "ideal"
    assert plan.config.sim.rangefinder.noise_m == 0.2  # the mission's key over the overlay
    assert plan.config.sim.estimator.grade == "rtk"  # the overlay's
    # --set chooses over the mission
    plan = load_mission(str(mission), ["sim.profile=realistic"])
    assert plan.config.sim.profile == "realistic"
    assert plan.config.sim.estimator.grade != "rtk"


def test_an_unknown_profile_is_refused_where_it_was_written():
    with pytest.raises(ConfigError) as err:
        load_config(overrides=["sim.profile=kind"])
    assert "--set: sim.profile:" in str(err.value)
    assert "realistic" in str(err.value)


def test_the_shipped_profiles_are_valid():
    from autopilot.config import PROFILES

    for name in PROFILES:
        assert load_config(overrides=[f"sim.profile={name}"]).sim.profile == name
