"""MAVLink 2 message signing, as PX4 and ArduPilot implement it (pymavlink does the work).

A link with a key signs everything it sends (SHA-256 over key, frame and a 48-bit timestamp
in 10 µs since 2015-01-01, link id) and drops what arrives unsigned or badly signed, apart from
the few messages that radios inject on their own (RADIO_STATUS, as ArduPilot and PX4 allow).
Replayed messages (a timestamp not newer than the last one of that sender's stream) and
messages more than a minute older than the link's clock are dropped too. A stream is a
(link id, system, component) triple, and its last timestamp is kept once per key, not per port:
a frame captured on one port and replayed to another is still a replay (the signing
specification's one timestamp per stream, wherever the frame arrives).

Key files (``--signing-key FILE``) hold the 32-byte secret key as 64 hexadecimal digits, as
32 raw bytes, or as a passphrase whose SHA-256 is the key (what MAVProxy's ``signing setup
PASSPHRASE`` and QGroundControl do, so the same passphrase works in all three).
"""

from __future__ import annotations

import hashlib
import re
import struct
import time
import types
from dataclasses import dataclass
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

#: 2015-01-01T00:00:00Z, the epoch of signing timestamps
SIGNING_EPOCH_S = 1_420_070_400
#: messages accepted unsigned on a signed link (radios generate them themselves)
UNSIGNED_ALLOWED = frozenset({mavlink.MAVLINK_MSG_ID_RADIO_STATUS})


class SigningKeyError(ValueError):
    """A key file that cannot be read or used."""


def signing_timestamp(now_s: float | None = None) -> int:
    """Now, in the signing protocol's units (10 µs since 2015-01-01)."""
    return int(((time.time() if now_s is None else now_s) - SIGNING_EPOCH_S) * 100_000)


@dataclass(frozen=True, slots=True)
class Signing:
    key: bytes
    link_id: int = 0

    def __post_init__(self) -> None:
        if len(self.key) != 32:
            raise SigningKeyError(f"a signing key has 32 bytes, this one {len(self.key)}")
        if not 0 <= self.link_id <= 255:
            raise SigningKeyError(f"link id {self.link_id} is not 0..255")

    @classmethod
    def load(cls, path: str | Path, link_id: int = 0) -> Signing:
        path = Path(path)
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise SigningKeyError(f"{path}: cannot read the signing key: "
                                  f"{exc.strerror or exc}") from None
        return cls(key_from_bytes(raw, str(path)), link_id)

    def apply(self, tx, rx, streams: dict | None = None) -> None:
        """Sign what ``tx`` (a pymavlink MAVLink) sends; accept only signed messages on ``rx``
        (which may be the same object). Call :func:`refresh` on ``tx`` before each send.
        ``streams``: the replay state (last timestamp per stream) ``rx`` shares with the other
        ports that take this key (None: its own)."""
        now = signing_timestamp()
        tx.signing.secret_key = self.key
        tx.signing.sign_outgoing = True
        tx.signing.link_id = self.link_id
        tx.signing.timestamp = max(tx.signing.timestamp, now)
        rx.signing.secret_key = self.key
        rx.signing.timestamp = max(rx.signing.timestamp, now)
        rx.signing.allow_unsigned_callback = _allow_unsigned
        if streams is not None:
            rx.signing.stream_timestamps = streams
        # verify before believing a frame's timestamp (see _check_signature)
        rx.check_signature = types.MethodType(_check_signature, rx)


def refresh(mav) -> None:
    """Keep a signing sender's timestamp on the clock: pymavlink only adds one tick per frame,
    so a quiet or slow link would fall behind real time, and a peer that starts listening a
    minute later would take its frames for replays."""
    if mav.signing.sign_outgoing:
        mav.signing.timestamp = max(mav.signing.timestamp, signing_timestamp())


def _allow_unsigned(mav, msg_id: int) -> bool:
    return msg_id in UNSIGNED_ALLOWED


def authenticated(msg, signing: Signing | None) -> bool:
    """Whether ``msg`` proves who sent it: any message on a link without a key; on a signed
    link only a signed one (RADIO_STATUS is taken unsigned for what it says, never as proof
    of its sender, so it may not move a link's peer)."""
    return signing is None or bool(msg.get_signed())


def _check_signature(mav, msgbuf, src_system: int, src_component: int) -> bool:
    """pymavlink's check, in the safe order: the signature first, the stream's timestamp after.
    (pymavlink records a frame's timestamp before it checks the signature, so one forged frame
    claiming the vehicle's ids and a far-future time would make every genuine frame after it
    look like a replay.)"""
    signing = mav.signing
    digest = hashlib.sha256(signing.secret_key + bytes(msgbuf[:-6])).digest()[:6]
    if digest != bytes(msgbuf[-6:]):
        return False
    low, high = struct.unpack("<IH", bytes(msgbuf[-12:-6]))
    timestamp = low + (high << 32)
    stream = (msgbuf[-13], src_system, src_component)
    last = signing.stream_timestamps.get(stream)
    if last is not None:
        if timestamp <= last:
            return False  # a replay
    elif timestamp + 6_000_000 < max(signing.timestamp, signing_timestamp()):
        return False  # a new stream more than a minute old
    signing.stream_timestamps[stream] = timestamp
    signing.timestamp = max(signing.timestamp, timestamp)
    return True


def key_from_bytes(raw: bytes, where: str = "key") -> bytes:
    """The 32-byte key a key file's contents stand for (see the module docstring)."""
    if len(raw) == 32 and not re.fullmatch(rb"[\x20-\x7e]{32}", raw):
        return raw
    try:
        text = raw.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise SigningKeyError(f"{where}: neither 32 raw bytes, 64 hexadecimal digits nor a "
                              f"passphrase ({len(raw)} bytes of binary)") from None
    if re.fullmatch(r"[0-9a-fA-F]{64}", text):
        return bytes.fromhex(text)
    if not text:
        raise SigningKeyError(f"{where}: the signing key file is empty")
    return hashlib.sha256(text.encode("utf-8")).digest()
