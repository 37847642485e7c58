"""The AR.Drone 2.0 protocol codecs against the SDK 2.0 developer guide's own examples and
values seen on the wire (ARDroneLib, ardrone_autonomy): AT commands both ways, navdata both
ways with its checksum, and what malformed input does."""

import contextlib
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.ardrone import at, navdata
from drivers.ardrone.navdata import ControlState, Demo, NavdataError, State


def test_floats_travel_as_the_integers_with_their_bits():
    # the guide's example: -0.8 is 0xBF4CCCCD, sent as -1085485875
    assert at.float_arg(-0.8) == -1085485875
    assert at.float_arg(0.0) == 0
    assert at.float_arg(0.75) == 1061158912  # (a yaw of 0.75: a tutorial's example)
    assert at.arg_float(-1085485875) == pytest.approx(-0.8)


def test_ref_takes_off_lands_and_toggles_the_emergency_as_on_the_wire():
    c = at.AtCommands()
    assert c.ref(takeoff=True) == b"AT*REF=1,290718208\r"
    assert c.ref() == b"AT*REF=2,290717696\r"
    assert c.ref(emergency=True) == b"AT*REF=3,290717952\r"
    assert c.seq == 3


def test_pcmd_progressive_hover_and_clamping():
    c = at.AtCommands()
    assert c.pcmd(0.0, 0.0, 0.0, 0.75) == b"AT*PCMD=1,1,0,0,0,1061158912\r"
    assert c.pcmd(0.3, 0.3, 0.3, 0.3, hover=True) == b"AT*PCMD=2,0,0,0,0,0\r"
    (cmd,) = at.parse(c.pcmd(2.0, -0.8, -5.0, 0.0, combined_yaw=True))
    assert cmd.name == "PCMD"
    assert cmd.seq == 3
    assert cmd.args[0] == 3
    assert cmd.floats(1) == pytest.approx((1.0, -0.8, -1.0, 0.0))


def test_config_and_its_ids_quote_their_strings_and_refuse_quotes():
    c = at.AtCommands()
    assert c.config_ids("d2e081a3", "be27e2e4", "d87f7e0c") == \
        b'AT*CONFIG_IDS=1,"d2e081a3","be27e2e4","d87f7e0c"\r'
    assert c.config("control:altitude_max", 2000) == b'AT*CONFIG=2,"control:altitude_max","2000"\r'
    assert c.config("general:navdata_demo", True) == b'AT*CONFIG=3,"general:navdata_demo","TRUE"\r'
    with pytest.raises(at.AtError, match="quotes"):
        c.config("video:video_channel", 'x"y')
    with pytest.raises(at.AtError, match="ASCII"):
        c.config("video:video_channel", "é")
    assert c.comwdg() == b"AT*COMWDG=4\r"  # (the refused ones used no number)
    assert c.ftrim() == b"AT*FTRIM=5\r"
    c.restart()
    assert c.ctrl(5) == b"AT*CTRL=1,5,0\r"


def test_a_datagram_of_several_commands_either_line_end():
    commands = at.parse(b"AT*PCMD=21625,1,0,0,0,0\nAT*REF=21626,290717696\r")
    assert [(c.name, c.seq, c.args) for c in commands] == [
        ("PCMD", 21625, (1, 0, 0, 0, 0)), ("REF", 21626, (290717696,))]
    config = at.parse(b'AT*CONFIG=7,"video:video_channel","1"\r')[0]
    assert config.args == ("video:video_channel", "1")


def test_an_empty_last_argument_is_none():
    """The ``ardrone`` 0.2.1 client sends ``AT*NAME=seq,`` for a command without arguments."""
    commands = at.parse(b"AT*COMWDG=5,\rAT*FTRIM=6,\rAT*REF=7,290718208,\r")
    assert [(c.name, c.seq, c.args) for c in commands] == [
        ("COMWDG", 5, ()), ("FTRIM", 6, ()), ("REF", 7, (290718208,))]
    with pytest.raises(at.AtError):
        at.parse(b"AT*REF=7,,290718208\r")


@pytest.mark.parametrize("datagram", [
    b"AT*PCMD=1,1,0,0,0", b"PCMD=1,1", b"AT*FLY=1,0\r", b"AT*REF=x\r", b"AT*REF=1,99999999999\r",
    b'AT*CONFIG=1,"a\r', b"AT*REF=1,\xff\r", b"AT*COMWDG=1" + b"," + b"1" * 1100])
def test_malformed_commands_are_refused_with_a_reason(datagram):
    if len(datagram) > at.MAX_DATAGRAM:
        with pytest.raises(at.AtError, match="at most 1024"):
            at.parse(datagram)
        return
    if datagram == b"AT*PCMD=1,1,0,0,0":  # (a command without its line end is still one)
        assert at.parse(datagram)[0].args == (1, 0, 0, 0)
        return
    with pytest.raises(at.AtError):
        at.parse(datagram)


def test_commands_pack_into_datagrams_of_at_most_1024_bytes():
    c = at.AtCommands()
    commands = [c.pcmd(0.1, 0.2, 0.3, 0.4) for _ in range(60)]
    packed = at.datagrams(commands)
    assert len(packed) > 1
    assert all(len(d) <= at.MAX_DATAGRAM for d in packed)
    assert b"".join(packed) == b"".join(commands)
    assert [cmd.seq for d in packed for cmd in at.parse(d)] == list(range(1, 61))


def _demo(**changes) -> Demo:
    values = dict(control_state=(ControlState.HOVERING << 16) | 2, battery_percent=87,
                  theta_mdeg=-1500.0, phi_mdeg=250.5, psi_mdeg=-90000.0, altitude_mm=1012,
                  vx_mm_s=120.25, vy_mm_s=-33.0, vz_mm_s=4.5, frame_index=11)
    values.update(changes)
    return Demo(**values)


def test_a_demo_packet_is_148_bytes_of_demo_and_a_checksum_and_reads_back():
    state = State.FLY | State.NAVDATA_DEMO | State.COM_WATCHDOG
    packet = navdata.build(state, 42, _demo())
    assert len(packet) == 16 + 148 + 8
    assert packet[:4] == struct.pack("<I", 0x55667788)
    assert struct.unpack_from("<HHI", packet, 16 + 148) == \
        (0xFFFF, 8, sum(packet[:16 + 148]) & 0xFFFFFFFF)
    got = navdata.parse(packet)
    assert got.state == state
    assert State.EMERGENCY not in got.state
    assert got.sequence == 42
    assert got.demo == _demo()
    assert got.demo.major_state is ControlState.HOVERING


def test_bootstrap_packets_and_unknown_options():
    got = navdata.parse(navdata.build(State.NAVDATA_BOOTSTRAP, 1))
    assert got.demo is None
    assert got.options == {}
    raw = b"\x01\x02\x03\x04"
    got = navdata.parse(navdata.build(State.NAVDATA_DEMO, 2, _demo(), options={99: raw}))
    assert got.options[99] == raw  # a tag past navdata_common.h's: kept at its own size
    assert got.demo is not None


@pytest.mark.parametrize(("damage", "message"), [
    (lambda p: p[:10], "shorter than"),
    (lambda p: b"\x00\x00\x00\x00" + p[4:], "header 0x00000000"),
    (lambda p: p[:20] + bytes([p[20] ^ 1]) + p[21:], "checksum"),
    (lambda p: p[:16] + struct.pack("<HH", 0, 4000) + p[20:], "does not fit"),
    (lambda p: p[:16] + struct.pack("<HH", 0, 20) + p[20:36] + struct.pack("<HH", 0xFFFF, 8)
     + struct.pack("<I", sum(p[:16] + struct.pack("<HH", 0, 20) + p[20:36]) & 0xFFFFFFFF),
     "demo option of 20 bytes"),
])
def test_damaged_packets_are_refused_saying_what_is_wrong(damage, message):
    packet = navdata.build(State.NAVDATA_DEMO, 7, _demo())
    with pytest.raises(NavdataError, match=message):
        navdata.parse(damage(packet))


@given(st.binary(max_size=300))
def test_any_bytes_parse_or_are_refused_never_anything_else(data):
    with contextlib.suppress(NavdataError):
        navdata.parse(data)
    with contextlib.suppress(at.AtError):
        at.parse(data)
