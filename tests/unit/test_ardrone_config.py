"""The AR.Drone 2.0 configuration: its defaults against config_keys.h and values real drones
reported, AT*CONFIG's rules as the simulated firmware applies them, the text the drone sends
over TCP 5559 line by line, and the driver reading a dump shaped like a real drone's."""

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.ardrone import config
from drivers.ardrone.config import (
    KEYS,
    ConfigError,
    DroneConfig,
    Kind,
    ReadOnlyKeyError,
    UnknownKeyError,
    format_value,
    parse_config_text,
)

# a dump shaped like a real drone's: CRLF line ends, a calibration matrix wrapped over three
# lines, an empty value, keys this module does not model, the NULs that end the buffer
REAL_DUMP = (
    b"general:num_version_config = 1\r\n"
    b"general:num_version_mb = 33\r\n"
    b"general:num_version_soft = 2.4.8\r\n"
    b"general:soft_build_date = 2013-08-08 13:21\r\n"
    b"general:ardrone_name = My ARDrone\r\n"
    b"general:flying_time = 2217\r\n"
    b"general:navdata_demo = TRUE\r\n"
    b"general:com_watchdog = 2\r\n"
    b"control:accs_offset = { -2.2353198e+03 1.9247540e+03 2.0844270e+03 }\r\n"
    b"control:accs_gains = { 1.0109735e+00 2.3000900e-02 4.1132037e-02\r\n"
    b" -4.2992691e-03 -9.9152333e-01 2.8609591e-02\r\n"
    b" 1.2049361e-02 -6.9085114e-02 -9.8430282e-01 }\r\n"
    b"control:altitude_max = 3000\r\n"
    b"control:outdoor = FALSE\r\n"
    b"network:ssid_single_player = ardrone2_047510\r\n"
    b"network:passkey =\r\n"
    b"pic:ultrasound_freq = 8\r\n"
    b"general:navdata_options = 65537\r\n"
    b"control:euler_angle_max = 2.0943999e-01\r\n"
    b"control:control_vz_max = 7.0000000e+02\r\n"
    b"control:control_yaw = 1.7278759e+00\r\n"
    b"video:video_codec = 129\r\n"
    b"video:video_channel = 0\r\n"
    b"custom:session_id = 00000000\r\n"
    b"\x00\x00\x00"
)
# the last line cut by the buffer's NULs, no line end after it
CUT_DUMP = b"general:navdata_demo = TRUE\r\ncustom:profile_id = 00000000\x00\x00"


def _line(text: str, key: str) -> str:
    (line,) = [ln for ln in text.splitlines(keepends=True) if ln.startswith(key + " ")]
    return line


def test_the_text_is_the_drones_own_lines():
    text = DroneConfig().to_text()
    assert _line(text, "control:euler_angle_max") == "control:euler_angle_max = 2.0943999e-01\n"
    assert _line(text, "control:control_vz_max") == "control:control_vz_max = 7.0000000e+02\n"
    assert _line(text, "control:control_yaw") == "control:control_yaw = 1.7453293e+00\n"
    assert _line(text, "control:altitude_max") == "control:altitude_max = 3000\n"
    assert _line(text, "general:navdata_demo") == "general:navdata_demo = FALSE\n"
    assert _line(text, "general:video_enable") == "general:video_enable = TRUE\n"
    assert _line(text, "general:navdata_options") == "general:navdata_options = 65537\n"
    assert _line(text, "video:video_codec") == "video:video_codec = 129\n"  # 0x81: H264_360P
    assert _line(text, "general:num_version_soft") == "general:num_version_soft = 2.4.8\n"
    assert text.endswith("custom:session_desc = Default session configuration\n")
    assert "\r" not in text
    assert "\0" not in text


def test_floats_print_as_cs_percent_7e_of_their_single_precision_value():
    assert format_value(Kind.FLOAT, 0.20944) == "2.0943999e-01"  # what a real drone reports
    assert format_value(Kind.FLOAT, 12000 * 1.745329252e-05) == "2.0943952e-01"  # config_keys.h
    assert format_value(Kind.FLOAT, 0.0) == "0.0000000e+00"
    assert format_value(Kind.FLOAT, -4.2992691e-03) == "-4.2992691e-03"
    assert format_value(Kind.BOOL, True) == "TRUE"
    assert format_value(Kind.INT, 102400) == "102400"


def test_keys_are_listed_by_category_common_appli_user_session():
    names = [line.split(" = ")[0] for line in DroneConfig().to_text().splitlines()]
    order = [config.KEYS_BY_NAME[n].category for n in names]
    assert order == sorted(order)
    # as a real dump: navdata_options (application) after the common keys, the channel last
    assert names.index("syslog:nb_files") < names.index("general:navdata_options")
    assert names.index("control:euler_angle_max") < names.index("video:video_channel")
    assert len(names) == len(set(names)) == len(KEYS)


def test_every_default_passes_its_own_rules():
    for key in KEYS:
        value = config._parse(key, format_value(key.kind, key.default))
        if key.kind is Kind.FLOAT:
            assert value == pytest.approx(key.default, rel=1e-7), key.name
        else:
            assert value == key.default, key.name


def test_the_defaults_the_autopilot_flies_on():
    c = DroneConfig()
    assert c.euler_angle_max_rad == pytest.approx(0.20944, abs=1e-7)
    assert c.control_vz_max_mm_s == 700.0
    assert c.control_yaw_rad_s == pytest.approx(1.7453293)
    assert (c.altitude_max_mm, c.altitude_min_mm) == (3000, 50)
    assert c.get_int("video:codec_fps") == 30
    assert c.get_int("video:video_channel") == 0
    assert c.get_str("network:ssid_single_player").startswith("ardrone2_")
    assert c.get_bool("general:navdata_demo") is False


def test_an_unknown_key_is_refused_as_a_key_error():
    c = DroneConfig()
    with pytest.raises(UnknownKeyError, match="control:no_such_key"):
        c.set("control:no_such_key", "1")
    with pytest.raises(KeyError):  # (the simulated firmware catches KeyError or ValueError)
        c.set("nosection", "1")
    with pytest.raises(ValueError, match="video:nothing"):
        c.get("video:nothing")


def test_read_only_keys_are_refused():
    c = DroneConfig()
    for key in ("general:num_version_soft", "general:vbat_min", "general:flying_time",
                "video:camif_fps", "pic:pic_version"):
        with pytest.raises(ReadOnlyKeyError, match="read-only"):
            c.set(key, "1")
    assert c.get("general:vbat_min") == 9000


def test_session_keys_are_written_only_under_a_custom_configuration():
    c = DroneConfig()
    for key, text in (("video:video_codec", "131"), ("video:max_bitrate", "2000"),
                      ("video:codec_fps", "15"), ("video:bitrate_ctrl_mode", "1")):
        with pytest.raises(ReadOnlyKeyError, match="multiconfig"):
            c.set(key, text)
        assert c.set(key, text, custom=True) == {key: int(text)}
    assert c.get_int("video:video_codec") == 0x83
    assert c.set("video:video_channel", "1") == {"video:video_channel": 1}  # this one: any


def test_keys_match_in_any_case_and_are_stored_under_their_own_name():
    c = DroneConfig()
    assert c.set("CONTROL:altitude_max", "5000") == {"control:altitude_max": 5000}
    assert c.get("control:altitude_max") == 5000
    assert c.get("Control:Altitude_Max") == 5000


@pytest.mark.parametrize(("key", "text"), [
    ("control:euler_angle_max", "abc"),
    ("control:euler_angle_max", "0,25"),  # a decimal comma (the real drone read it as 0)
    ("control:euler_angle_max", "nan"),
    ("control:euler_angle_max", "inf"),
    ("control:euler_angle_max", ""),
    ("control:altitude_max", "1_000"),
    ("control:altitude_max", "3000.5"),
    ("control:altitude_max", "0x1000"),
    ("general:com_watchdog", str(2**31)),
    ("general:navdata_demo", "yes"),
    ("general:navdata_demo", "1"),
    ("general:ardrone_name", "x" * 128),
    ("general:ardrone_name", "two\nlines"),
    ("general:ardrone_name", "caf\u00e9"),
])
def test_a_value_that_does_not_read_as_its_type_is_refused_and_nothing_changes(key, text):
    c = DroneConfig()
    before = c.to_text()
    with pytest.raises(ConfigError):
        c.set(key, text)
    assert c.to_text() == before


def test_values_read_as_their_types():
    c = DroneConfig()
    assert c.set("control:altitude_max", "3000.0") == {"control:altitude_max": 3000}
    assert c.set("control:altitude_max", " +4000 ") == {"control:altitude_max": 4000}
    assert c.set("general:navdata_demo", "true") == {"general:navdata_demo": True}
    assert c.set("general:navdata_demo", "FALSE") == {"general:navdata_demo": False}
    assert c.set("control:control_vz_max", "1e3")["control:control_vz_max"] == 1000.0
    value = c.set("control:euler_angle_max", "0.3")["control:euler_angle_max"]
    assert value != 0.3
    assert value == struct.unpack("<f", struct.pack("<f", 0.3))[0]  # kept in single precision
    assert c.set("general:ardrone_name", "") == {"general:ardrone_name": ""}
    assert c.set("general:navdata_options", "4194305") == {"general:navdata_options": 4194305}


@pytest.mark.parametrize(("key", "inside", "outside"), [
    ("control:euler_angle_max", ("0", "0.52", "0.1"), ("-0.01", "0.53", "1.0")),
    ("control:outdoor_euler_angle_max", ("0.35",), ("0.6",)),
    ("control:control_vz_max", ("200", "2000", "700.0"), ("199", "2001", "0")),
    ("control:indoor_control_vz_max", ("1000",), ("100",)),
    ("control:control_yaw", ("0.6982", "6.11", "1.75"), ("0.69", "6.12", "0")),
    ("control:altitude_max", ("500", "100000", "20000"), ("499", "100001", "-1")),
    ("video:video_channel", ("0", "1"), ("2", "3", "4", "-1")),
    ("pic:ultrasound_freq", ("7", "8"), ("9", "0")),
    ("detect:enemy_colors", ("1", "3"), ("0", "4")),
])
def test_the_guides_ranges_and_values(key, inside, outside):
    for text in inside:
        c = DroneConfig()
        c.set(key, text)
        assert c.get(key) == pytest.approx(float(text), rel=1e-6), (key, text)
    for text in outside:
        c = DroneConfig()
        before = c.get(key)
        with pytest.raises(ConfigError, match=key):
            c.set(key, text)
        assert c.get(key) == before, (key, text)


def test_the_frame_rate_and_codec_under_a_custom_configuration():
    c = DroneConfig()
    with pytest.raises(ConfigError, match="30"):
        c.set("video:codec_fps", "31", custom=True)
    with pytest.raises(ConfigError, match="one of"):
        c.set("video:video_codec", "64", custom=True)  # P264: AR.Drone 1.0's
    assert c.set("video:video_codec", str(0x88), custom=True) == {"video:video_codec": 0x88}


def test_outdoor_loads_its_profile_and_a_limit_is_saved_to_the_profile_in_use():
    c = DroneConfig()
    changed = c.set("control:outdoor", "TRUE")
    assert set(changed) == {"control:outdoor", "control:euler_angle_max",
                            "control:control_vz_max", "control:control_yaw"}
    assert c.euler_angle_max_rad == pytest.approx(0.34906584)
    assert c.control_vz_max_mm_s == 1000.0
    assert c.control_yaw_rad_s == pytest.approx(3.4906585)
    c.set("control:euler_angle_max", "0.3")
    assert c.get_float("control:outdoor_euler_angle_max") == pytest.approx(0.3)
    assert c.get_float("control:indoor_euler_angle_max") == pytest.approx(0.20944)
    c.set("control:outdoor", "FALSE")
    assert c.euler_angle_max_rad == pytest.approx(0.20944)
    assert c.set("control:indoor_control_yaw", "2.0") == {"control:indoor_control_yaw": 2.0,
                                                         "control:control_yaw": 2.0}
    assert c.set("control:outdoor_control_yaw", "3.0") == {"control:outdoor_control_yaw": 3.0}
    assert c.control_yaw_rad_s == 2.0


def test_typed_getters_refuse_the_wrong_type():
    c = DroneConfig()
    assert isinstance(c.get_float("control:euler_angle_max"), float)
    with pytest.raises(TypeError, match="float, not int"):
        c.get_int("control:euler_angle_max")
    with pytest.raises(TypeError):
        c.get_bool("control:altitude_max")
    with pytest.raises(TypeError):
        c.get_str("general:navdata_demo")


def test_the_drones_own_values_bypass_client_rights_but_not_types():
    c = DroneConfig({"general:flying_time": 2217, "network:ssid_single_player": "ardrone2_1",
                     "general:navdata_demo": True, "control:euler_angle_max": 0.1})
    assert c.get("general:flying_time") == 2217
    assert "network:ssid_single_player = ardrone2_1\n" in c.to_text()
    assert c.get("general:navdata_demo") is True
    assert c.euler_angle_max_rad == pytest.approx(0.1)
    with pytest.raises(UnknownKeyError):
        DroneConfig({"general:nope": 1})
    with pytest.raises(ConfigError):
        DroneConfig({"control:euler_angle_max": 3.0})


def test_the_defaults_round_trip_through_the_text():
    c = DroneConfig()
    assert parse_config_text(c.to_text()) == dict(c.items())


def _writable_value(key: config.Key) -> st.SearchStrategy[str]:
    if key.choices is not None:
        return st.sampled_from(sorted(key.choices)).map(str)
    if key.kind is Kind.BOOL:
        return st.sampled_from(["TRUE", "FALSE", "true", "False"])
    if key.kind is Kind.STRING:
        return st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=40)
    lo, hi = key.limits or (-2**31, 2**31 - 1)
    if key.kind is Kind.INT:
        return st.integers(int(lo), int(hi)).map(str)
    return st.floats(lo, hi).map(repr)


_WRITABLE = [k for k in KEYS if k.write != config.NONE]


@given(st.lists(st.sampled_from(_WRITABLE).flatmap(
    lambda k: st.tuples(st.just(k.name), _writable_value(k))), max_size=25))
def test_any_valid_sets_round_trip_through_the_text(sets):
    c = DroneConfig()
    for name, text in sets:
        c.set(name, text, custom=True)
    text = c.to_text()
    values = parse_config_text(text)
    assert DroneConfig(values).to_text() == text  # the text is its own fixed point
    assert values.keys() == dict(c.items()).keys()
    for name, value in c.items():  # (%.7e keeps 8 digits: a float may come back 1 ulp off)
        if isinstance(value, float):
            assert values[name] == pytest.approx(value, rel=2e-7), name
        else:
            assert values[name] == value, name


def test_a_dump_shaped_like_a_real_drones():
    values = parse_config_text(REAL_DUMP)
    assert values["general:num_version_soft"] == "2.4.8"
    assert values["general:navdata_demo"] is True
    assert values["general:flying_time"] == 2217
    assert values["control:euler_angle_max"] == pytest.approx(0.20944)
    assert values["control:control_yaw"] == pytest.approx(1.7278759)
    assert values["control:control_vz_max"] == 700.0
    assert values["video:video_codec"] == 0x81
    assert values["network:ssid_single_player"] == "ardrone2_047510"
    assert values["network:passkey"] == ""
    assert values["general:num_version_mb"] == "33"  # not modelled: kept as text
    assert values["general:soft_build_date"] == "2013-08-08 13:21"
    assert values["control:accs_offset"] == pytest.approx((-2235.3198, 1924.754, 2084.427))
    assert len(values["control:accs_gains"]) == 9
    assert values["control:accs_gains"][8] == pytest.approx(-0.98430282)
    assert values["custom:session_id"] == "00000000"
    assert len(values) == 22
    # the same as text with bare LF line ends, or CR alone
    assert parse_config_text(REAL_DUMP.decode().replace("\r\n", "\n")) == values
    assert parse_config_text(REAL_DUMP.decode().replace("\r\n", "\r")) == values


def test_nuls_that_end_a_line_are_not_part_of_its_value():
    assert parse_config_text(CUT_DUMP) == {"general:navdata_demo": True,
                                           "custom:profile_id": "00000000"}
    assert parse_config_text(b"control:altitude_max = 4000\x00\n") == {
        "control:altitude_max": 4000}


def test_stray_lines_repeats_and_a_vector_never_closed():
    text = ("\n  \nnot a key line\n=3\ncontrol:altitude_max = 3000\n"
            "control:altitude_max=4000\nCONTROL:Outdoor = true\n"
            "control:accs_offset = { 1 2\ncontrol:altitude_min = 60\n"
            "general:ardrone_name = {no brace closes and = signs\nvideo:video_channel = 1\n")
    values = parse_config_text(text)
    assert values == {"control:altitude_max": 4000, "control:outdoor": True,
                      "control:accs_offset": (1.0, 2.0), "control:altitude_min": 60,
                      "general:ardrone_name": "{no brace closes and = signs",
                      "video:video_channel": 1}


@given(st.text(max_size=300) | st.binary(max_size=300))
def test_parsing_never_raises(text):
    assert isinstance(parse_config_text(text), dict)
