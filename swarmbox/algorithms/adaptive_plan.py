"""Geometry, global planning and potential fields of the adaptive swarm (see ``.adaptive``).

Obstacles are the mission's static obstacles as given in its config: ``{kind: segment, a, b,
radius_m}``, ``{kind: box, center, size}`` or ``{kind: circle, center, radius_m}``, [north, east]
metres, infinite height. Points are 2-D numpy arrays in the same plane.
"""

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

Obstacles = Sequence[Mapping[str, Any]]


def surface(obstacle: Mapping[str, Any], n: float, e: float) -> tuple[float, float, float, float, float]:
    """Nearest surface point (n, e) of ``obstacle`` to the point (n, e), the signed distance to it
    (negative inside) and the outward unit normal (n, e) there."""
    kind, r = obstacle["kind"], 0.0
    if kind == "box":
        (cn, ce), (sn, se) = obstacle["center"], obstacle["size"]
        dn, de, hn, he = n - cn, e - ce, sn / 2, se / 2
        if abs(dn) < hn and abs(de) < he:          # inside: leave through the nearest face
            sn_, se_ = math.copysign(1.0, dn), math.copysign(1.0, de)
            if hn - abs(dn) < he - abs(de):
                return cn + sn_ * hn, e, abs(dn) - hn, sn_, 0.0
            return n, ce + se_ * he, abs(de) - he, 0.0, se_
        qn, qe = cn + min(max(dn, -hn), hn), ce + min(max(de, -he), he)
    elif kind == "circle":
        (qn, qe), r = obstacle["center"], float(obstacle["radius_m"])
    elif kind == "segment":
        (an, ae), (bn, be) = obstacle["a"], obstacle["b"]
        abn, abe = bn - an, be - ae
        t = min(max(((n - an) * abn + (e - ae) * abe) / max(abn * abn + abe * abe, 1e-12), 0.0), 1.0)
        qn, qe, r = an + t * abn, ae + t * abe, float(obstacle.get("radius_m", 0.1))
    else:
        raise ValueError(f"unknown obstacle kind {kind!r}")
    d = max(math.hypot(n - qn, e - qe), 1e-9)
    un, ue = (n - qn) / d, (e - qe) / d
    return qn + un * r, qe + ue * r, d - r, un, ue


def clearance(obstacles: Obstacles, n: float, e: float) -> float:
    """Distance from (n, e) to the nearest obstacle surface (inf without obstacles)."""
    return min((surface(ob, n, e)[2] for ob in obstacles), default=math.inf)


def edge_free(obstacles: Obstacles, a: np.ndarray, b: np.ndarray, margin_m: float) -> bool:
    """Whether the straight edge a→b keeps ``margin_m`` from every obstacle (checked every margin/2)."""
    steps = max(1, math.ceil(math.dist(a, b) / max(margin_m / 2, 0.05)))
    (an, ae), (dn, de) = a.tolist(), (b - a).tolist()
    return all(clearance(obstacles, an + dn * k / steps, ae + de * k / steps) > margin_m
               for k in range(steps + 1))


def rrt(start: np.ndarray, goal: np.ndarray, obstacles: Obstacles, bounds: np.ndarray,
        rng: np.random.Generator, p: Mapping[str, float]) -> list[np.ndarray] | None:
    """A rapidly-exploring random tree from ``start`` to ``goal``; the path, or None after
    ``p['rrt_max_iters']`` samples. ``bounds`` is [[n_min, e_min], [n_max, e_max]]; each extension is
    at most ``rrt_step_m`` long (never past its sample); the goal is sampled with ``rrt_goal_bias``."""
    margin, step = float(p["clearance_m"]), float(p["rrt_step_m"])
    nodes = np.empty((int(p["rrt_max_iters"]) + 2, 2))
    nodes[0], parent, count = start, [-1], 1
    for _ in range(int(p["rrt_max_iters"])):
        sample = goal if rng.random() < float(p["rrt_goal_bias"]) else rng.uniform(bounds[0], bounds[1])
        dist = np.hypot(*(nodes[:count] - sample).T)
        k = int(np.argmin(dist))
        if dist[k] < 1e-6:
            continue
        new = nodes[k] + (sample - nodes[k]) * min(1.0, step / dist[k])
        if not edge_free(obstacles, nodes[k], new, margin):
            continue
        nodes[count], count = new, count + 1
        parent.append(k)
        if np.hypot(*(goal - new)) <= step and edge_free(obstacles, new, goal, margin):
            path, i = [goal], count - 1
            while i >= 0:
                path.append(nodes[i].copy())
                i = parent[i]
            return path[::-1]
    return None


def shortcut(path: list[np.ndarray], obstacles: Obstacles, rng: np.random.Generator,
             iters: int, margin_m: float) -> list[np.ndarray]:
    """Random shortcutting: join two random points of the path by a straight edge when it is free."""
    path = [np.asarray(q, float) for q in path]
    for _ in range(iters):
        seg = np.hypot(*np.diff(np.array(path), axis=0).T)
        cum = np.concatenate(([0.0], np.cumsum(seg)))
        s1, s2 = np.sort(rng.uniform(0.0, cum[-1], size=2))
        i, j = np.searchsorted(cum, s1, "right") - 1, np.searchsorted(cum, s2, "right") - 1
        if j <= i:
            continue
        g1 = path[i] + (path[i + 1] - path[i]) * (s1 - cum[i]) / max(seg[i], 1e-12)
        g2 = path[j] + (path[j + 1] - path[j]) * (s2 - cum[j]) / max(seg[j], 1e-12)
        if edge_free(obstacles, g1, g2, margin_m):
            path = path[:i + 1] + [g1, g2] + path[j + 1:]
    return path


def resample(path: list[np.ndarray], spacing_m: float) -> list[tuple[float, float]]:
    """Points every ``spacing_m`` along the path, keeping every corner and the end."""
    out = [tuple(path[0].tolist())]
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = int(np.ceil(np.hypot(*(b - a)) / spacing_m))
        out += [tuple((a + (b - a) * k / n).tolist()) for k in range(1, n + 1)]
    return out


def avoid(obstacles: Obstacles, pos: np.ndarray, v: np.ndarray, influence_m: float,
          gain: float) -> np.ndarray:
    """``v`` (2,) made safe near obstacles: for each obstacle surface nearer than ``influence_m`` the part
    of ``v`` heading into it is removed in proportion to the closeness (fully at contact, so the drone
    slides along it), and a potential-field push ``gain · (1/d − 1/d0) / d²`` along the outward normal
    is added."""
    vn, ve = v.tolist()
    n, e = pos.tolist()
    for ob in obstacles:
        _, _, d, un, ue = surface(ob, n, e)
        if d < influence_m:
            d = max(d, 0.05)
            inward = min(vn * un + ve * ue, 0.0) * (1.0 - d / influence_m)
            k = gain * (1.0 / d - 1.0 / influence_m) / (d * d) - inward
            vn, ve = vn + k * un, ve + k * ue
    return np.array([vn, ve])


def away_from(others: np.ndarray, pos: np.ndarray, range_m: float, gain: float) -> np.ndarray:
    """Linear push (2,) away from each of ``others`` (M, 2) nearer than ``range_m``."""
    if not len(others):
        return np.zeros(2)
    off = pos - others
    d = np.maximum(np.hypot(off[:, 0], off[:, 1]), 1e-6)
    w = gain * np.maximum(range_m - d, 0.0) / d
    return (w[:, None] * off).sum(axis=0)


def cap(v: np.ndarray, limit: float) -> np.ndarray:
    """``v`` scaled down to norm ``limit`` if longer."""
    n = float(np.hypot(*v))
    return v * (limit / n) if n > limit else v
