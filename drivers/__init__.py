"""Everything below the vehicle interface: the interface itself (:mod:`drivers.base`), clocks,
hand-over slots, and the drivers (the MuJoCo simulator in :mod:`drivers.sim`)."""
