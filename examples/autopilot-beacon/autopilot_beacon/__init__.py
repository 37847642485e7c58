"""An example plugin for the autopilot: a coloured beacon lying on the ground (the target kind
``beacon``: its scenario section, its simulated body, its configuration section and its
perception pipeline) and ``hover_beacon`` (a step kind: find the beacon with the down camera
and hover over it; its metrics, its terminal figures and its report panel).

Nothing in the autopilot names it: it arrives through the ``autopilot.targets`` and
``autopilot.steps`` entry points declared in this package's ``pyproject.toml``.
"""
