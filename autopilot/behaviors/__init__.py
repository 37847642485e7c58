"""Mission behaviours: one lifecycle each (activate → update … → status), synchronous.

A behaviour never talks to the vehicle: it returns setpoints and *requests* (arm, take off,
start offboard, hold, land) that the runtime carries out and reports back.
"""
