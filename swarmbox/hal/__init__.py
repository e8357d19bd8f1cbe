"""Hardware abstraction: the Vehicle protocol and its backends (``sim``, ``px4``, ``mavsim``).

Backends never import each other. Adding one = a module implementing :class:`Backend` and
:class:`Vehicle` plus a file in ``conf/backend/``.
"""
