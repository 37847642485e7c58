"""autopilot: camera-guided quadrotor missions for PX4 / MAVLink vehicles."""

__version__ = "0.1.0"
