"""The rangefinder as the simulated flight stack's estimator takes it: never the raw reading.

A rangefinder gives outliers (a missed return reads its maximum range, debris reads short) and
dropouts. PX4's EKF2 takes a reading into its height above ground only through an innovation
gate (EKF2_RNG_GATE, against what the estimate predicts), and resets to the new value when the
ground has really changed (a step, a deck) and the readings stay there; ArduCopter uses a
filtered rangefinder altitude. Both land detectors judge "near the ground" on that, so a single
12 m outlier under a vehicle sitting on the ground never makes it "in the air" (which refused
NAV_TAKEOFF with "already flying" on the realistic profile).

:class:`RangeGate` does the same: a reading within ``gate_m`` (plus a share of the distance) of
the prediction — the last accepted reading carried on by the estimated vertical velocity, or,
without a recent one, the estimated height above home — is taken; one outside is set aside
(the prediction stands in for it) unless readings outside that agree with each other go on
for ``persist_s`` (the ground has changed: independent outliers do not agree), when the newest
is taken. No reading (NaN: below its minimum range, out of range, lost) stays NaN.
"""

from __future__ import annotations

import math

#: a reading further than this from the prediction (m, plus RELATIVE_GATE of the distance) is
#: set aside
GATE_M = 0.5
RELATIVE_GATE = 0.2
#: readings outside the gate this long: the ground has changed, take them
PERSIST_S = 0.3
#: readings outside the gate further apart than this are not one run
RUN_GAP_S = 0.1
#: a last accepted reading older than this no longer predicts the next (the estimate does)
STALE_S = 1.0


class RangeGate:
    def __init__(self, gate_m: float = GATE_M, persist_s: float = PERSIST_S) -> None:
        self.gate_m = gate_m
        self.persist_s = persist_s
        self._last_m: float | None = None
        self._last_s = -math.inf
        #: the run of readings outside the gate: (when it began, its newest reading, when)
        self._outside: tuple[float, float, float] | None = None
        #: readings set aside so far
        self.rejected = 0

    def height(self, now_s: float, reading_m: float, est, home_ned_m) -> float:
        """:meth:`update` with the estimate's vertical velocity and height above ``home_ned_m``
        (the estimate's origin while there is no home)."""
        home_z = float(home_ned_m[2]) if home_ned_m is not None else 0.0
        return self.update(now_s, reading_m, float(est.velocity_ned_m_s[2]),
                           home_z - float(est.position_ned_m[2]))

    def update(self, now_s: float, reading_m: float, vz_ned_m_s: float,
               height_above_home_m: float) -> float:
        """The height above ground the flight stack uses for ``reading_m`` now."""
        if not math.isfinite(reading_m):
            self._outside = None  # (no reading: a run of outside ones is broken)
            return reading_m
        if self._last_m is not None and now_s - self._last_s <= STALE_S:
            predicted = self._last_m - vz_ned_m_s * (now_s - self._last_s)
        else:
            predicted = max(height_above_home_m, 0.0)
        if self._within(reading_m, predicted):
            return self._take(now_s, reading_m)
        # outside: a run of readings that agree with each other is the ground changing;
        # outliers, independent, do not agree
        run = self._outside
        if run is None or now_s - run[2] > RUN_GAP_S or not self._within(reading_m, run[1]):
            self._outside = (now_s, reading_m, now_s)
        elif now_s - run[0] >= self.persist_s:
            return self._take(now_s, reading_m)
        else:
            self._outside = (run[0], reading_m, now_s)
        self.rejected += 1
        return predicted

    def _within(self, reading_m: float, expected_m: float) -> bool:
        return abs(reading_m - expected_m) <= self.gate_m + RELATIVE_GATE * abs(expected_m)

    def _take(self, now_s: float, reading_m: float) -> float:
        self._last_m, self._last_s, self._outside = reading_m, now_s, None
        return reading_m
