"""The shipped target kinds, one module each, registered in :mod:`autopilot.targets`: the ball
(follow_ball), the marker board (follow_marker), the image on the ground (hover_image), the
landing pad (land_pad) and the rover with its deck (land_on_rover).

Each module holds everything of its kind that is not perception or estimation proper: its
scenario section and world builder, its configuration sections, its checks. Importing this
package registers them, in this order (the order their bodies are added to the simulated world
and their sections appear in the models); the scenario and configuration models are made after
it. To add a shipped kind: write its module, call :func:`~autopilot.targets.register_target`,
and import it below; another package's kinds arrive through the ``autopilot.targets`` entry
point group (:mod:`autopilot.plugins`).
"""

from importlib import import_module

#: the shipped kinds' modules, in the order they are registered
SHIPPED = ("ball", "marker", "image", "pad", "rover", "keep_out")

for _name in SHIPPED:
    import_module(f"{__name__}.{_name}")
