"""Estimation: target filters and the vehicle-pose history they need (synchronous)."""
