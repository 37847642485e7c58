"""The simulator's ground truth of a flight log as columns (scoring only: the autopilot never
sees it): read in one pass over ``/sim/ground_truth``, one float per number, not a dict per
sample. Every metric that scores against the truth works from these columns, so a long flight's
end-of-run metrics hold a few numbers per sample, not its records (see :class:`~autopilot.
flightlog.log.StoredLog`).
"""

from __future__ import annotations

import dataclasses
import math
from array import array
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from autopilot.flightlog import records as ch


def extend_floats(column: array, values, size: int) -> None:
    """Append a vector of ``size`` numbers to a float column: NaN for a null vector or a null
    inside one (NaN in the file)."""
    if values is None:
        column.extend((math.nan,) * size)
        return
    n = len(column)
    try:
        column.extend(values)
    except TypeError:  # (what it took before the null goes: the vector is taken again)
        del column[n:]
        column.extend(math.nan if v is None else v for v in values)


class _Columns:
    def __init__(self) -> None:
        self.index = array("q")  # the sample's row in the table
        self.p, self.v, self.q = array("d"), array("d"), array("d")


@dataclass(frozen=True, slots=True)
class BodyTrack:
    """The samples in which one body was present: time, the vehicle's position, velocity and
    attitude (w, x, y, z), the body's position, velocity and attitude (NaN where the log did
    not have them)."""

    t: np.ndarray
    vehicle_p: np.ndarray
    vehicle_v: np.ndarray
    vehicle_q: np.ndarray
    p: np.ndarray
    v: np.ndarray
    q: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    def window(self, keep: np.ndarray) -> BodyTrack:
        return BodyTrack(self.t[keep], self.vehicle_p[keep], self.vehicle_v[keep],
                         self.vehicle_q[keep], self.p[keep], self.v[keep], self.q[keep])


class TruthTable:
    """Ground-truth samples as columns: ``t``, the vehicle's ``p``, ``v``, ``q`` (NaN where a
    sample had none, ``has_vehicle`` False), each body's track (:meth:`body`), and the last
    sample with the vehicle as logged (:attr:`last`: its flight-stack state, ``armed``,
    ``mode``, …)."""

    def __init__(self, samples: Iterable[Mapping]) -> None:
        t, p, v, q = array("d"), array("d"), array("d"), array("d")
        has_vehicle = array("b")
        bodies: dict[str, _Columns] = {}
        last: Mapping | None = None
        n = 0
        for s in samples:
            t.append(s["time_s"])
            position = s.get("vehicle_position_ned_m")
            has_vehicle.append(position is not None)
            extend_floats(p, position, 3)
            extend_floats(v, s.get("vehicle_velocity_ned_m_s"), 3)
            extend_floats(q, s.get("vehicle_attitude_q"), 4)
            for name, body in (s.get("bodies") or {}).items():
                columns = bodies.get(name)
                if columns is None:
                    columns = bodies[name] = _Columns()
                columns.index.append(n)
                extend_floats(columns.p, body.get("position_ned_m"), 3)
                extend_floats(columns.v, body.get("velocity_ned_m_s"), 3)
                extend_floats(columns.q, body.get("attitude_q"), 4)
            if position is not None:
                last = s
            n += 1
        self.t = np.frombuffer(t, dtype=float) if n else np.zeros(0)
        self.p = np.frombuffer(p, dtype=float).reshape(n, 3) if n else np.zeros((0, 3))
        self.v = np.frombuffer(v, dtype=float).reshape(n, 3) if n else np.zeros((0, 3))
        self.q = np.frombuffer(q, dtype=float).reshape(n, 4) if n else np.zeros((0, 4))
        self.has_vehicle = np.frombuffer(has_vehicle, dtype=np.int8).astype(bool)
        for column in (self.t, self.p, self.v, self.q, self.has_vehicle):
            column.flags.writeable = False  # (shared by every step's metrics)
        self.last = last
        self._bodies = bodies
        self._tracks: dict[str, BodyTrack] = {}

    def __len__(self) -> int:
        return len(self.t)

    def body(self, name: str) -> BodyTrack:
        """The samples in which ``name`` was present (none: an empty track)."""
        track = self._tracks.get(name)
        if track is None:
            columns = self._bodies.get(name)
            if columns is None:
                index = np.zeros(0, dtype=int)
                own = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 4)))
            else:
                index = np.frombuffer(columns.index, dtype=np.int64)
                k = len(index)
                if k and index[-1] - index[0] == k - 1:  # every sample from its first: views
                    index = slice(int(index[0]), int(index[0]) + k)
                own = (np.frombuffer(columns.p, dtype=float).reshape(k, 3),
                       np.frombuffer(columns.v, dtype=float).reshape(k, 3),
                       np.frombuffer(columns.q, dtype=float).reshape(k, 4))
            track = self._tracks[name] = BodyTrack(self.t[index], self.p[index], self.v[index],
                                                   self.q[index], *own)
            for field in dataclasses.fields(track):
                getattr(track, field.name).flags.writeable = False  # (shared by every step's)
        return track


def truth_table(log: Mapping[str, Sequence[Mapping]]) -> TruthTable:
    """The log's ground truth as columns (read once per :class:`~autopilot.flightlog.log.
    StoredLog`; for records in memory, made on each call)."""
    derived = getattr(log, "derived", None)
    if derived is None:
        return TruthTable(log.get(ch.GROUND_TRUTH, []))
    table = derived.get(ch.GROUND_TRUTH)
    if table is None:
        table = derived[ch.GROUND_TRUTH] = TruthTable(log.get(ch.GROUND_TRUTH, []))
    return table
