"""Perception: detectors turning camera frames into measurements (synchronous, no event loop)."""
