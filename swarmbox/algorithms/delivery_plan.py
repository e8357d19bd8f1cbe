"""Delivery planning, independent of flight: packages, sorting rules, assignment methods, the
message codec shared by the ground and the drones, and the dataset generators.

Everything here is a pure function of its inputs, so the benchmark's nine strategies can be checked
without flying (see ``tests/algorithms/test_delivery.py``).

Sorting rules (``params.sort``), applied to the packages before assignment; ties keep package-id
order (Python's sort is stable; the reference's ``std::sort`` was not, so its tie order differs):

- ``none``: package-id order, i.e. the order in which the dataset was generated;
- ``azimuth``: ascending azimuth ``atan2(east, north)`` in (-pi, pi] around the origin;
- ``distance``: ascending distance ``hypot(north, east)`` from the origin (the depot).

Assignment methods (``params.assign``) over the sorted positions p = 0..N-1 of N packages and the
fleet's drones in id order (index i = 0..size-1):

- ``block``: contiguous blocks, drone index ``floor(p * size / N)``. When size divides N this is the
  paper's ``floor(p / floor(N / size))`` (20 consecutive packages each for 100 and 5); otherwise the
  blocks differ by at most one package (the reference's formula ran past the last drone);
- ``rr``: round-robin, drone index ``p mod size``;
- ``dynamic``: nothing is planned; the ground hands out the next sorted package to a drone each time
  that drone reports its previous one delivered.
"""

from __future__ import annotations

import math
import random
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

SORTS = ("none", "azimuth", "distance")
ASSIGNS = ("block", "rr", "dynamic")

#: TaskCommand codes: the whole pre-assigned list (possibly empty), one dynamic package, no more work.
PLAN, NEXT, END = 0, 1, 2


class Package(NamedTuple):
    """One delivery: its id (the mission ``values`` key) and drop-off point in the mission frame."""

    id: int
    north_m: float
    east_m: float


class Strategy(NamedTuple):
    """One of the nine allocation algorithms: a sorting rule and an assignment method."""

    sort: str
    assign: str

    @property
    def preplanned(self) -> bool:
        return self.assign != "dynamic"


def strategy_of(params: Mapping[str, Any]) -> Strategy:
    """The strategy named by an algorithm's ``params``; a clear error for unknown names."""
    sort, assign = str(params.get("sort", "")), str(params.get("assign", ""))
    if sort not in SORTS:
        raise ValueError(f"delivery: unknown sort '{sort}'; allowed values: {', '.join(SORTS)}")
    if assign not in ASSIGNS:
        raise ValueError(f"delivery: unknown assign '{assign}'; allowed values: {', '.join(ASSIGNS)}")
    return Strategy(sort, assign)


def packages_of(values: Mapping[int, Sequence[float]]) -> list[Package]:
    """Packages from mission ``values`` (id -> [north, east, ...]), in id order."""
    out = []
    for pid in sorted(values):
        point = values[pid]
        if len(point) < 2:
            raise ValueError(f"delivery: package {pid} needs [north, east], got {list(point)}")
        out.append(Package(int(pid), float(point[0]), float(point[1])))
    return out


def sort_packages(packages: Sequence[Package], rule: str) -> list[Package]:
    """The packages in the order of sorting ``rule`` (see the module docstring)."""
    by_id = sorted(packages, key=lambda p: p.id)
    if rule == "none":
        return by_id
    if rule == "azimuth":
        return sorted(by_id, key=lambda p: math.atan2(p.east_m, p.north_m))
    if rule == "distance":
        return sorted(by_id, key=lambda p: math.hypot(p.north_m, p.east_m))
    raise ValueError(f"delivery: unknown sort '{rule}'; allowed values: {', '.join(SORTS)}")


def assign_packages(ordered: Sequence[Package], drones: Sequence[int],
                    method: str) -> dict[int, list[Package]]:
    """Pre-assign sorted packages to drones: drone id -> its packages, in sorted order."""
    if method not in ("block", "rr"):
        raise ValueError(f"delivery: '{method}' is not a pre-assignment method; use block or rr")
    size, count = len(drones), len(ordered)
    if size == 0:
        raise ValueError("delivery: no drone to assign packages to")
    plan: dict[int, list[Package]] = {d: [] for d in drones}
    for p, package in enumerate(ordered):
        index = p * size // count if method == "block" else p % size
        plan[drones[index]].append(package)
    return plan


def encode_packages(packages: Sequence[Package]) -> str:
    """``id:north:east`` per package, comma-separated (the TaskCommand ``data``)."""
    return ",".join(f"{p.id}:{p.north_m!r}:{p.east_m!r}" for p in packages)


def decode_packages(data: str) -> list[Package]:
    """Inverse of :func:`encode_packages`."""
    out = []
    for item in filter(None, data.split(",")):
        pid, north, east = item.split(":")
        out.append(Package(int(pid), float(north), float(east)))
    return out


def encode_ids(ids: Sequence[int]) -> str:
    """Delivered package ids, comma-separated (the drone's ``report_data``)."""
    return ",".join(str(i) for i in ids)


def decode_ids(data: str) -> list[int]:
    return [int(x) for x in data.split(",") if x]


def random_points(rng: np.random.Generator, count: int = 100,
                  half_size_m: float = 100.0) -> dict[int, list[float]]:
    """``count`` drop-off points uniform in the square [-half_size_m, half_size_m]^2 around the depot,
    rounded to 0.1 m: package id -> [north_m, east_m]. ``rng`` is the run's dataset stream."""
    if count < 0 or half_size_m <= 0:
        raise ValueError(f"random_points: need count >= 0 and half_size_m > 0, got {count}, {half_size_m}")
    points = np.round(rng.uniform(-half_size_m, half_size_m, size=(int(count), 2)), 1)
    return {i: [float(n), float(e)] for i, (n, e) in enumerate(points)}


def paper_points(rng: np.random.Generator | None = None, dataset: int = 1, count: int = 100,
                 dataset_offset: int = 0) -> dict[int, list[float]]:
    """The paper's RQ4 dataset k = ``dataset + dataset_offset`` (1..20 in the study), exactly.

    The original script seeds Python's generator with k and draws, per package, north then east as
    ``randint(-100, 100)``; a private ``random.Random(k)`` reproduces it without touching global
    state. ``rng`` is accepted for the generator hook and not used. The first 101 / 180 points of
    dataset 1 are the paper's RQ5 16- and 36-drone missions.
    """
    k = int(dataset) + int(dataset_offset)
    if count < 0:
        raise ValueError(f"paper_points: count must be >= 0, got {count}")
    draw = random.Random(k)
    points = {}
    for i in range(int(count)):
        north = draw.randint(-100, 100)
        east = draw.randint(-100, 100)
        points[i] = [float(north), float(east)]
    return points
