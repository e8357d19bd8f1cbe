"""The ``sim`` backend: a pymunk 2.5D fleet with a PX4-like autopilot per vehicle (:mod:`.backend`)."""
