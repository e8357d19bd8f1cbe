"""A mission area: the rectangle (and optional grid over it) that area-based algorithms read.

Coverage, demand and tracking missions all describe their area the same way in ``mission.values``::

    values:
      0: [north_min, east_min]   # m, mission frame
      1: [north_max, east_max]
      2: [rows, cols]            # a grid over the area (sectors, heat-map cells), if needed

:func:`mission_area` and :func:`mission_grid` read those entries once, with one error message that
names the algorithm and the missing or bad entry, so the algorithms do not each parse them their
own way. Re-exported by :mod:`swarmbox.api` (algorithms import it from there). The numbers are kept
as given (no conversion), so an algorithm computes exactly what it did from the raw values.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

__all__ = ["Area", "mission_area", "mission_grid"]

_AREA_KEYS = "0: [north_min, east_min] and 1: [north_max, east_max]"


class Area(NamedTuple):
    """An axis-aligned rectangle in the mission frame (m); unpacks as ``n0, e0, n1, e1``."""

    n_min: float
    e_min: float
    n_max: float
    e_max: float

    @property
    def center(self) -> tuple[float, float]:
        """The (north, east) centre."""
        return ((self.n_min + self.n_max) / 2, (self.e_min + self.e_max) / 2)

    @property
    def size(self) -> tuple[float, float]:
        """The (north, east) extent."""
        return (self.n_max - self.n_min, self.e_max - self.e_min)


def mission_area(values: Mapping[int, Sequence[float]], who: str) -> Area:
    """The area from ``values[0]`` and ``values[1]``; ``who`` (the algorithm) names the error.

    Raises ValueError when an entry is missing or shorter than two numbers, or the area is empty.
    """
    try:
        (n0, e0), (n1, e1) = values[0][:2], values[1][:2]
    except (KeyError, IndexError, TypeError, ValueError):
        raise ValueError(f"{who}: mission.values needs {_AREA_KEYS} (the area)") from None
    if not (n1 > n0 and e1 > e0):
        raise ValueError(f"{who}: empty area {list(values[0])} .. {list(values[1])}")
    return Area(n0, e0, n1, e1)


def mission_grid(values: Mapping[int, Sequence[float]], who: str, min_cells: int = 1) -> tuple[int, int]:
    """The ``(rows, cols)`` grid from ``values[2]``, each at least ``min_cells``.

    Raises ValueError naming ``who`` when the entry is missing, not two integers, or too small.
    """
    try:
        rows, cols = int(values[2][0]), int(values[2][1])
    except (KeyError, IndexError, TypeError, ValueError):
        raise ValueError(f"{who}: mission.values needs 2: [rows, cols] (a grid over the area)") from None
    if rows < min_cells or cols < min_cells:
        raise ValueError(f"{who}: grid {list(values[2])} needs at least {min_cells} rows and columns")
    return (rows, cols)
