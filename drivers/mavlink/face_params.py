"""The parameter protocol of the simulator's MAVLink face, as PX4 speaks it.

* PARAM_REQUEST_LIST: every parameter, in index order, ``param_count`` the total;
* PARAM_REQUEST_READ: by name (index −1) or by index; unknown ones get no answer (as PX4);
* PARAM_SET: the new value, echoed as PARAM_VALUE. A set the vehicle refuses (unknown name,
  wrong type, out of range) is answered with the unchanged value and a STATUSTEXT saying why,
  so that a client sees the refusal rather than waiting for a timeout.

Values travel as PX4 sends them: REAL32 parameters as floats, INT32 ones *bytewise* (the int's
four bytes in the float field, MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE), which is how
MAVSDK, QGroundControl and MAVProxy decode a PX4 vehicle's integers.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from typing import Protocol

from pymavlink.dialects.v20 import common as mavlink

from drivers.sim.flight.params import ParamError, ParamSpec, ParamType

log = logging.getLogger(__name__)

_TYPES = {ParamType.FLOAT: mavlink.MAV_PARAM_TYPE_REAL32,
          ParamType.INT32: mavlink.MAV_PARAM_TYPE_INT32}


class ParameterStore(Protocol):
    """What the face needs of a vehicle with parameters (the simulator driver)."""

    def param_specs(self) -> list[ParamSpec]: ...

    def param(self, name: str) -> float: ...

    async def set_param(self, name: str, value: float) -> float: ...


def encode_value(spec: ParamSpec, value: float) -> float:
    """PARAM_VALUE.param_value for ``value``: INT32 bytewise, as PX4."""
    if spec.type is ParamType.INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_value(param_type: int, raw: float) -> float:
    """The value a PARAM_SET carries (INT32 bytewise, as PX4 expects)."""
    if param_type in (mavlink.MAV_PARAM_TYPE_INT32, mavlink.MAV_PARAM_TYPE_UINT32,
                      mavlink.MAV_PARAM_TYPE_INT16, mavlink.MAV_PARAM_TYPE_UINT16,
                      mavlink.MAV_PARAM_TYPE_INT8, mavlink.MAV_PARAM_TYPE_UINT8):
        return float(struct.unpack("<i", struct.pack("<f", raw))[0])
    return float(raw)


def param_name(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode(errors="replace")
    return raw.rstrip("\x00")


class ParamServer:
    """Answers one vehicle's parameter messages. ``send(link, msg)`` sends on a link,
    ``spawn(coro)`` runs a coroutine owned by the face, ``say(link, text, severity)`` sends
    a STATUSTEXT."""

    def __init__(self, store: ParameterStore, send: Callable, spawn: Callable,
                 say: Callable) -> None:
        self.store = store
        self._send = send
        self._spawn = spawn
        self._say = say
        self._specs = store.param_specs()
        self._index = {spec.name: i for i, spec in enumerate(self._specs)}

    def value_message(self, mav, name: str):
        spec = self._specs[self._index[name]]
        return mav.param_value_encode(name.encode(), encode_value(spec, self.store.param(name)),
                                      _TYPES[spec.type], len(self._specs), self._index[name])

    def on_request_list(self, link, msg) -> None:
        for spec in self._specs:
            self._send(link, self.value_message(link.mav, spec.name))

    def on_request_read(self, link, msg) -> None:
        if msg.param_index >= 0:
            if msg.param_index >= len(self._specs):
                return
            name = self._specs[msg.param_index].name
        else:
            name = param_name(msg.param_id)
        if name in self._index:
            self._send(link, self.value_message(link.mav, name))

    def on_set(self, link, msg) -> None:
        name = param_name(msg.param_id)
        if name not in self._index:
            self._say(link, f"[pm] unknown param: {name}", 4)
            return
        spec = self._specs[self._index[name]]
        if msg.param_type != _TYPES[spec.type]:
            self._say(link, f"[pm] param types mismatch: {name} is {spec.type.value}", 4)
            self._send(link, self.value_message(link.mav, name))
            return
        value = decode_value(msg.param_type, msg.param_value)
        self._spawn(self._set(link, name, value))

    @staticmethod
    def refusal_text(name: str, reason: str) -> str:
        return f"[pm] {name}: {reason}"  # PX4's parameter module

    async def _set(self, link, name: str, value: float) -> None:
        try:
            await self.store.set_param(name, value)
        except ParamError as exc:
            log.info("parameter set refused: %s", exc)
            self._say(link, self.refusal_text(name, exc.reason), 4)
        self._send(link, self.value_message(link.mav, name))

