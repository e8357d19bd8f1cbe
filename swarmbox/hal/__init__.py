"""Hardware abstraction: the Vehicle protocol and its backends.

``vehicle`` (the Vehicle and Backend protocols), ``safety`` (the setpoint monitor every backend runs)
and ``launch`` (shared by process launchers) serve the backend subpackages: ``sim`` (pymunk 2.5D),
``px4`` (PX4 over MAVLink, with the shared ``mavlink`` codec and link) and ``mavsim`` (the px4
bridge flying processes with sim dynamics). ``sim`` and ``px4`` never import each other; only
``mavsim`` composes both. Adding a backend = a subpackage implementing :class:`~.vehicle.Backend`
plus a file in ``swarmbox/conf/backend/`` (docs/architecture.md; checked by import contracts).
"""
