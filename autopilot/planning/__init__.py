"""Trajectory planning for the offboard step kinds (``goto``, ``orbit``, ``survey``): paths,
time laws within the vehicle's limits, photo points, and the geometry they are scored by."""
