"""The simulated vehicle's signed ports (issue 31): an unsigned RADIO_STATUS is read for what
it says but cannot take a port's replies from the ground station, and a signed frame captured on
one port and replayed to another is refused (one replay state per key, as the signing
specification keeps one timestamp per stream wherever a frame arrives)."""

from __future__ import annotations

from types import SimpleNamespace

from pymavlink.dialects.v20 import common as mavlink

from drivers.mavlink.face import MavlinkFace
from drivers.mavlink.face_link import FaceLink, FaceStats
from drivers.mavlink.signing import Signing, refresh

KEY = Signing(bytes(range(32)))
GCS = ("127.0.0.1", 14550)
ATTACKER = ("127.0.0.1", 40000)


def _face(signing=KEY):
    received: list = []

    def receive(link, msg) -> None:  # (the face counts BAD_DATA; it is not obeyed)
        if msg.get_type() != "BAD_DATA":
            received.append((link.name, msg))

    face = SimpleNamespace(system_id=1, rover_system_id=2, signing=signing, signed_streams={},
                           dialect=MavlinkFace.dialect,
                           stats=FaceStats(), impairment=SimpleNamespace(fault=lambda: None),
                           incoming=SimpleNamespace(receive=receive))
    return face, received


def _signed_sender(system_id=255, component_id=190) -> mavlink.MAVLink:
    mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    KEY.apply(mav, mavlink.MAVLink(None))
    return mav


def _frame(mav: mavlink.MAVLink, msg) -> bytes:
    refresh(mav)
    return msg.pack(mav)


def test_an_unsigned_radio_status_is_read_but_does_not_move_the_reply_address():
    face, received = _face()
    link = FaceLink("gcs", face, default_peer=GCS)
    gcs = _signed_sender()
    link._parse(_frame(gcs, gcs.heartbeat_encode(6, 8, 0, 0, 4)), GCS)
    assert link.peer == GCS
    attacker = mavlink.MAVLink(None, srcSystem=51, srcComponent=68)  # no key
    for _ in range(20):
        link._parse(attacker.radio_status_encode(200, 180, 90, 40, 30, 0, 0).pack(attacker),
                    ATTACKER)
    assert link.peer == GCS  # the ground station keeps the stream
    kinds = [m.get_type() for _, m in received]
    assert kinds.count("RADIO_STATUS") == 20  # taken for what it says
    # an unsigned heartbeat from the attacker is dropped outright
    link._parse(attacker.heartbeat_encode(6, 8, 0, 0, 4).pack(attacker), ATTACKER)
    assert link.peer == GCS
    assert [m.get_type() for _, m in received].count("HEARTBEAT") == 1


def test_without_a_key_any_valid_sender_is_answered():
    face, _ = _face(signing=None)
    link = FaceLink("gcs", face, default_peer=GCS)
    radio = mavlink.MAVLink(None, srcSystem=51, srcComponent=68)
    link._parse(radio.radio_status_encode(200, 180, 90, 40, 30, 0, 0).pack(radio), ATTACKER)
    assert link.peer == ATTACKER


def test_a_signed_frame_replayed_to_another_port_is_refused():
    face, received = _face()
    offboard = FaceLink("offboard", face, default_peer=("127.0.0.1", 14540))
    gcs = FaceLink("gcs", face, default_peer=GCS)
    companion = _signed_sender(system_id=1, component_id=191)
    arm = _frame(companion, companion.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    offboard._parse(arm, ("127.0.0.1", 14540))
    assert [(name, m.get_type()) for name, m in received] == [("offboard", "COMMAND_LONG")]
    gcs._parse(arm, ATTACKER)  # captured on one port, replayed byte for byte to the other
    offboard._parse(arm, ATTACKER)  # and to the same port
    assert len(received) == 1
    assert gcs.peer == GCS
    assert offboard.peer == ("127.0.0.1", 14540)
    # the sender's next frame, on either port, is fine
    gcs._parse(_frame(companion, companion.command_long_encode(1, 1, 400, 0, 0, 0, 0, 0, 0, 0,
                                                                0)), ("127.0.0.1", 14541))
    assert [(name, m.get_type()) for name, m in received][-1] == ("gcs", "COMMAND_LONG")
