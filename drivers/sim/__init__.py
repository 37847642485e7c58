"""The MuJoCo simulator: a PX4-equivalent quadrotor that the rest of the project flies.

Headless rendering needs an OpenGL backend; EGL (Mesa's, software on machines without a GPU)
is the default here unless ``MUJOCO_GL`` says otherwise. This must happen before MuJoCo loads.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
