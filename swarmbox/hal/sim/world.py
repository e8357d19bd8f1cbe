"""The horizontal half of the 2.5D world: one pymunk body per drone, static obstacles, contacts.

The plane is the north–east plane: pymunk x = north, y = east (:func:`ned_xy` is the only place that
knows it). Bodies never rotate (infinite moment), so pymunk's handedness is irrelevant. Linear drag
is pymunk's velocity damping: ``v *= exp(-drag/mass · dt)`` per step, exact for any step length.

State goes in and out through pymunk's batch iterators (:mod:`pymunk.batch`) in one C call each way,
so a tick costs a fixed handful of C calls whatever the fleet size. The iterator calls are prepared
once (:class:`_BatchCall`): ``pymunk.batch``'s wrappers build a new descriptor on every call, which
cost more than the iteration itself at a few drones. Contacts between two drones are processed only when their
altitude gap is within ``vertical_separation_m`` and not both are on the ground; each contact that
starts being processed is reported once through ``emit``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import Any

import numpy as np
import pymunk
import pymunk.batch as pb

from swarmbox.hal.sim.params import SimParams

DRONE, OBSTACLE = 1, 2
_GET = pb.BodyFields.POSITION | pb.BodyFields.VELOCITY
_SET = pb.BodyFields.VELOCITY | pb.BodyFields.FORCE
_SET_FORCE = pb.BodyFields.FORCE
_GETTER, _SETTER = "pmSpaceBodyGetIteratorFuncBatched", "pmSpaceBodySetIteratorFuncBatched"

#: emit(drone_id, name, data): report a collision that began.
Emit = Callable[[int, str, dict[str, Any]], None]


def ned_xy(ned: np.ndarray) -> np.ndarray:
    """The components of an axis-first NED array ``(3, ...)`` that live in the pymunk plane, as
    (x, y) = (north, east).

    Returns a view, so it converts both ways: read it for NED → plane, assign into it for
    plane → NED.
    """
    return ned[0:2]


class PlaneWorld:
    """pymunk space of N drone bodies (in home order) plus static obstacles.

    ``alt_d_m``, ``vel_d_m_s`` and ``airborne`` (1.0 flying, 0.0 on the ground) are the fleet's
    live vertical state (N,), read by the contact filter. Write commands into :attr:`cmd_vel_xy` /
    :attr:`cmd_force_xy` (views (2, N)) before :meth:`step`; read the state back with :meth:`read`.
    """

    def __init__(self, homes_ned_m: np.ndarray, p: SimParams, obstacles: Sequence[Mapping[str, Any]],
                 alt_d_m: np.ndarray, vel_d_m_s: np.ndarray, airborne: np.ndarray, emit: Emit) -> None:
        self.n, self._p, self._emit = homes_ned_m.shape[1], p, emit
        self._alt, self._vd, self._air = alt_d_m, vel_d_m_s, airborne
        self.space = pymunk.Space()
        self.space.damping = math.exp(-p.drag_n_s_m / p.mass_kg)
        self.space.collision_slop = 0.01   # m of overlap tolerated (pymunk's default 0.1 suits pixels)
        self._drone_of: dict[pymunk.Shape, int] = {}
        self._obstacle_of: dict[pymunk.Shape, tuple[int, str]] = {}
        self._touching: set[tuple[int, int]] = set()
        self.bodies = [self._add_drone(i, xy) for i, xy in enumerate(ned_xy(homes_ned_m).T.tolist())]
        for k, spec in enumerate(obstacles):
            shape = _obstacle_shape(self.space.static_body, k, spec)
            shape.collision_type, shape.elasticity, shape.friction = OBSTACLE, p.elasticity, p.friction
            self.space.add(shape)
            self._obstacle_of[shape] = (k, str(spec["kind"]))
        self.space.on_collision(DRONE, DRONE, pre_solve=self._pre_drones, separate=self._separate)
        self.space.on_collision(DRONE, OBSTACLE, pre_solve=self._pre_obstacle, separate=self._separate)
        self._init_batch(self._check_body_order())

    def _init_batch(self, rows: int) -> None:
        """Persistent batch buffers for ``rows`` bodies (the drones first, then static bodies)."""
        # The batch getter appends into this array in place (it only reallocates when nearly full,
        # and the slack keeps it far from that), so reading costs no allocation.
        self._get_arr = np.zeros(rows * 4 + 16)
        self._get_buf = pb.Buffer()
        self._get_buf.set_float_buf(self._get_arr)
        raw = self._get_arr[:rows * 4].reshape(rows, 4)   # per body: x, y, vx, vy
        self._raw_pos, self._raw_vel = raw[:self.n, 0:2].T, raw[:self.n, 2:4].T
        self._set_arr = np.zeros((rows, 4))     # per body: vx, vy, fx, fy (static bodies' rows stay 0)
        self._force_arr = np.zeros((rows, 2))
        self._set_buf, self._force_buf = pb.Buffer(), pb.Buffer()
        self._set_buf.set_float_buf(self._set_arr)
        self._force_buf.set_float_buf(self._force_arr)
        self.cmd_vel_xy = self._set_arr[:self.n, 0:2].T
        self.cmd_force_xy = self._set_arr[:self.n, 2:4].T
        self._get = _BatchCall(self.space, _GET, self._get_buf, _GETTER)
        self._set = _BatchCall(self.space, _SET, self._set_buf, _SETTER)
        self._set_force = _BatchCall(self.space, _SET_FORCE, self._force_buf, _SETTER)
        self._get_num = self._get_buf._float_arr   # the getter's fill count, reset before each read
        self._get_num.num = 0
        self._get()
        if np.frombuffer(self._get_buf.float_buf()).ctypes.data != self._get_arr.ctypes.data:
            raise RuntimeError("pymunk batch buffer was reallocated")

    def _add_drone(self, i: int, xy: Sequence[float]) -> pymunk.Body:
        body = pymunk.Body(self._p.mass_kg, math.inf)
        body.position = (xy[0], xy[1])
        shape = pymunk.Circle(body, self._p.radius_m)
        shape.collision_type, shape.elasticity, shape.friction = DRONE, self._p.elasticity, self._p.friction
        self.space.add(body, shape)
        self._drone_of[shape] = i
        return body

    def _check_body_order(self) -> int:
        """The batch API walks bodies in the space's order: dynamic bodies first, as added."""
        buf = pb.Buffer()
        pb.get_space_bodies(self.space, pb.BodyFields.BODY_ID, buf)
        ids = np.frombuffer(buf.int_buf(), dtype=np.uintp)
        if ids[:self.n].tolist() != [b.id for b in self.bodies]:
            raise RuntimeError("pymunk batch body order differs from insertion order")
        return len(ids)

    # ---- per tick ------------------------------------------------------------------------------
    def read(self, pos_ned_m: np.ndarray, vel_ned_m_s: np.ndarray) -> None:
        """Copy the bodies' plane positions and velocities into axis-first NED arrays (3, N)."""
        self._get_num.num = 0
        self._get()
        np.copyto(ned_xy(pos_ned_m), self._raw_pos)
        np.copyto(ned_xy(vel_ned_m_s), self._raw_vel)

    def step(self, dt_s: float, substeps: int) -> None:
        """Apply the commanded velocities and forces, then advance the space by ``dt_s``."""
        self._set()
        h = dt_s / substeps
        self._space_step(h)
        if substeps > 1:   # pymunk clears forces after every step: re-apply them
            self._force_arr[:self.n] = self._set_arr[:self.n, 2:4]
            for _ in range(substeps - 1):
                self._set_force()
                self._space_step(h)

    def _space_step(self, h: float) -> None:
        """The first step through ``Space.step`` (it checks the bodies added), the others straight into
        chipmunk: bodies and shapes are only added in the constructor, and the contact callbacks
        never add or remove anything, so ``Space.step``'s bookkeeping has nothing left to do."""
        self.space.step(h)
        self._space_step = partial(pb.lib.cpSpaceStep, self.space._space)

    # ---- contacts ------------------------------------------------------------------------------
    def _pre_drones(self, arb: pymunk.Arbiter, _space: pymunk.Space, _data: Any) -> None:
        sa, sb = arb.shapes
        i, j = sorted((self._drone_of[sa], self._drone_of[sb]))
        gap_m = abs(float(self._alt[i] - self._alt[j]))
        real = gap_m <= self._p.vertical_separation_m and bool(self._air[i] or self._air[j])
        arb.process_collision = real
        if not real:
            self._touching.discard((i, j))
        elif (i, j) not in self._touching:
            self._touching.add((i, j))
            dv = self.bodies[i].velocity - self.bodies[j].velocity
            rel = math.sqrt(dv.x * dv.x + dv.y * dv.y + float(self._vd[i] - self._vd[j]) ** 2)
            self._emit(i, "drone_drone", {"other_id": j, "rel_speed_m_s": rel, "alt_gap_m": gap_m})

    def _pre_obstacle(self, arb: pymunk.Arbiter, _space: pymunk.Space, _data: Any) -> None:
        sa, sb = arb.shapes
        i, (k, kind) = self._drone_of[sa], self._obstacle_of[sb]
        real = bool(self._air[i])
        arb.process_collision = real
        key = (i, -1 - k)
        if not real:
            self._touching.discard(key)
        elif key not in self._touching:
            self._touching.add(key)
            v = self.bodies[i].velocity
            speed = math.sqrt(v.x * v.x + v.y * v.y + float(self._vd[i]) ** 2)
            self._emit(i, "drone_obstacle", {"obstacle": k, "obstacle_kind": kind, "rel_speed_m_s": speed,
                                             "alt_m": -float(self._alt[i])})

    def _separate(self, arb: pymunk.Arbiter, _space: pymunk.Space, _data: Any) -> None:
        sa, sb = arb.shapes
        i, j = self._drone_of.get(sa), self._drone_of.get(sb)
        if i is None:   # the space is being torn down
            return
        if j is not None:
            self._touching.discard((min(i, j), max(i, j)))
        elif sb in self._obstacle_of:
            self._touching.discard((i, -1 - self._obstacle_of[sb][0]))


class _BatchCall:
    """One prepared pymunk batch iteration over every body of a space: what
    ``pymunk.batch.get_space_bodies`` / ``set_space_bodies`` do, with the descriptor built once.

    A setter reads its buffer from the start (``num = 0``) and leaves ``num`` as it was, as
    ``set_space_bodies`` does; a getter appends at ``num`` (the caller resets it).
    """

    __slots__ = ("_call", "_args", "_arr", "_setter")

    def __init__(self, space: pymunk.Space, fields: pb.BodyFields, buf: pb.Buffer, func: str) -> None:
        data = pb.ffi.new("pmBatchedData *")
        data.fields = fields.value
        data.floatArray, data.intArray = buf._float_arr, buf._int_arr
        self._call = pb.lib.cpSpaceEachBody
        self._args = (space._space, pb.ffi.addressof(pb.lib, func), data, buf)   # buf: kept alive
        self._arr = buf._float_arr
        self._setter = func == _SETTER

    def __call__(self) -> None:
        space, func, data, _ = self._args
        if self._setter:
            arr = self._arr
            num, arr.num = arr.num, 0
            self._call(space, func, data)
            arr.num = num
        else:
            self._call(space, func, data)


def _obstacle_shape(static: pymunk.Body, k: int, spec: Mapping[str, Any]) -> pymunk.Shape:
    """One static obstacle (infinite height) from its config mapping; ValueError names bad input."""
    kind = spec.get("kind")
    try:
        if kind == "segment":
            a, b = _xy(spec["a"]), _xy(spec["b"])
            return pymunk.Segment(static, a, b, float(spec.get("radius_m", 0.1)))
        if kind == "circle":
            return pymunk.Circle(static, float(spec["radius_m"]), _xy(spec["center"]))
        if kind == "box":
            (cn, ce), (sn, se) = _xy(spec["center"]), _xy(spec["size"])
            if sn <= 0 or se <= 0:
                raise ValueError("size must be positive")
            corners = [(cn + sn / 2 * u, ce + se / 2 * w) for u, w in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            return pymunk.Poly(static, corners)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"obstacle {k} ({kind}): {exc!r}") from exc
    raise ValueError(f"obstacle {k}: unknown kind {kind!r} (segment, box or circle)")


def _xy(ne: Sequence[float]) -> tuple[float, float]:
    """An obstacle's [n, e] pair as a pymunk point."""
    arr = np.asarray(ne, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"expected [n, e], got {ne!r}")
    x, y = ned_xy(arr).tolist()
    return (x, y)
