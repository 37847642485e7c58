"""A seed rule's cmd_vel as the AR.Drone's own progressive command (Setpoint.progressive): the
signs ardrone_autonomy hands the SDK (src/teleop_twist.cpp), the clamping, the auto-hover."""

from __future__ import annotations

import numpy as np

from autopilot.control.ardrone import ArDroneTiltModel, Twist
from drivers.base import ProgressiveCommand


def test_the_axes_and_signs_are_ardrone_autonomys() -> None:
    command = Twist(linear_x=0.5, linear_y=0.3, linear_z=-0.2, angular_z=0.4).progressive()
    # forward is nose down (pitch < 0), left is roll < 0, + angular.z (left) is yaw < 0
    assert command == ProgressiveCommand(roll=-0.3, pitch=-0.5, gaz=-0.2, yaw=-0.4,
                                         hover=False)


def test_clamped_and_zero_is_the_auto_hover() -> None:
    assert Twist(linear_x=3.0).progressive().pitch == -1.0
    assert Twist().progressive().hover
    # angular x/y non-zero disable the auto-hover: zero then means level, no command
    level = Twist(angular_x=1.0).progressive()
    assert not level.hover
    assert (level.roll, level.pitch, level.gaz, level.yaw) == (0.0, 0.0, 0.0, 0.0)


def test_the_tilt_models_setpoints_carry_the_command() -> None:
    model = ArDroneTiltModel()
    sp = model.step(Twist(linear_x=0.5), 0.0, 0.0, np.zeros(3))
    assert sp.progressive == ProgressiveCommand(pitch=-0.5, hover=False)
    assert model.step(Twist(), 0.1, 0.0, np.zeros(3)).progressive.hover
