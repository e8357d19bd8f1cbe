"""Contexts: the narrow façade a hook receives over the node that runs it.

Everything here reads the node through a handful of attributes and methods; nothing hands out a
node, a message tuple, a backend object or ground truth.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, final

from swarmbox.api.types import (
    DescendantState,
    DroneState,
    InferiorReport,
    MissionInfo,
    PeerState,
    Stage,
    Task,
    Vec3,
)

if TYPE_CHECKING:  # only for type checkers: the node classes stay out of the user's namespace
    import numpy as np


class _Context:
    """What both kinds of context share."""

    __slots__ = ("_node",)

    def __init__(self, node: Any) -> None:
        self._node = node

    @property
    def stage(self) -> Stage:
        return self._node.stage

    @property
    def tick(self) -> int:
        """Ticks since this node entered its current stage: 0 on the entry tick (the tick its
        ``*_once`` hook ran), the same on the ground and on every drone."""
        return self._node.stage_tick

    @property
    def time_s(self) -> float:
        """This node's local clock."""
        return self._node.clock.now()

    @property
    def stage_time_s(self) -> float:
        """Seconds since this node entered its current stage (ticks × tick period)."""
        return self._node.stage_tick * self._node.tick_s

    @property
    def tick_s(self) -> float:
        return self._node.tick_s

    @property
    def params(self) -> Mapping[str, Any]:
        """The algorithm's ``params`` from its config: this node's own read-only copy (a write raises
        ``TypeError``, and the run fails naming the hook; lists come as tuples)."""
        return self._node.params

    @property
    def rng(self) -> np.random.Generator:
        """This node's own seeded random generator; use it for every random choice."""
        return self._node.rng

    @property
    def mission(self) -> MissionInfo:
        """The mission as configured: this node's own read-only copy (as ``params``)."""
        return self._node.mission

    def mark(self, name: str, **fields: Any) -> None:
        """Record a named event marker in this node's log.

        Field values must be JSON values: numbers, strings, booleans, None, and lists, tuples and
        string-keyed dicts of them; numpy scalars and arrays are converted. Anything else (an object
        whose text would hold a memory address, so that identical runs differ) is a TypeError
        naming the field. Markers turn into mission metrics in the analyzer (see ``metrics`` in
        the algo config).
        """
        self._node.mark(name, {key: json_value(value, f"ctx.mark({name!r}) field {key!r}")
                               for key, value in fields.items()})

    def send_task(self, dst: int, *, code: int = 0, waypoint_ned_m: Sequence[float] | None = None,
                  yaw_rad: float | None = None, data: str = "", reliable: bool = True) -> bool:
        """Send a task to a direct inferior ``dst``; returns whether it was sent.

        ``dst`` must be a drone of the mission other than this one (anything else is a ValueError).
        A drone that is not an alive direct inferior of this node *now* (a peer, a grandchild, an
        inferior that was lost or has not reported yet) gets nothing: the call returns False, and
        the refusal is logged (``error/task_refused``) and counted in run.json (``tasks_refused``).

        Reliable tasks (the default) are acknowledged and re-sent until they are, and reach the
        receiver's ``on_task`` exactly once and in send order, whatever the network loses or
        reorders; pass ``reliable=False`` for streams re-sent every tick (best effort: a lost one is
        gone, a late one may overtake nothing but is not held back either). ``code`` is any
        integer in 0..2**32-1 (codes below 128 take one byte on the wire); anything else is a
        ValueError here, in every runtime, rather than a frame the network cannot carry.
        """
        code = _task_code(code)
        node = self._node
        if dst not in node.alive_reports():
            _refuse_task(node, dst, code)
            return False
        wp = None if waypoint_ned_m is None else tuple(float(x) for x in waypoint_ned_m)
        node.send_task(dst, code, wp, None if yaw_rad is None else float(yaw_rad), data, reliable)
        return True


def _refuse_task(node: Any, dst: Any, code: int) -> None:
    """Log and count a task to a drone that is not an alive direct inferior; raise for a bad id."""
    if isinstance(dst, bool) or not isinstance(dst, int) or dst not in node.mission.initial_positions:
        raise ValueError(f"send_task: {dst!r} is not a drone of the mission "
                         f"(drones {sorted(node.mission.initial_positions)})")
    if dst == node.node_id:
        raise ValueError(f"send_task: drone {dst} cannot send a task to itself")
    lost = dst in node.inferiors
    why = "lost inferior" if lost else "not a direct inferior"
    node.event("error", "task_refused", dst, code=code, reason=why, alive=sorted(node.alive_reports()))
    node.tasks_refused += 1


_JSON_SCALARS = (str, int, float, bool, type(None))


def json_value(value: Any, where: str) -> Any:
    """``value`` as a JSON value (numpy converted, tuples as lists); a TypeError naming ``where``
    for anything else."""
    if isinstance(value, _JSON_SCALARS):
        return value
    if isinstance(value, list | tuple):
        return [json_value(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str | int) or isinstance(k, bool):
                raise TypeError(f"{where}: key {k!r} is a {type(k).__name__}; JSON keys are strings")
            out[k] = json_value(v, f"{where}[{k!r}]")
        return out
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):   # numpy scalars and arrays
        return json_value(value.tolist(), where)
    raise TypeError(f"{where} is a {type(value).__module__}.{type(value).__qualname__}, not a JSON value "
                    "(numbers, strings, booleans, None, and lists or dicts of them)")


def _task_code(code: Any) -> int:
    try:
        value = operator.index(code)
    except TypeError:
        value = None
    if value is None or isinstance(code, bool) or not 0 <= value <= 2**32 - 1:
        raise ValueError(f"task code must be an integer in 0..{2**32 - 1}, got {code!r}")
    return value


@final
class DroneContext(_Context):
    """What a drone's algorithm sees."""

    __slots__ = ()

    @property
    def id(self) -> int:
        return self._node.node_id

    @property
    def superior(self) -> int:
        """Current superior (-1 = the ground); changes on a handover."""
        return self._node.superior

    @property
    def state(self) -> DroneState:
        """Own state as the autopilot knows it (estimate, GNSS, armed, mode, battery)."""
        return self._node.own_state()

    @property
    def pos_ned_m(self) -> Vec3:
        """Own estimated position (NED, mission frame)."""
        return self._node.telemetry.pos_ned_m

    @property
    def vel_ned_m_s(self) -> Vec3:
        return self._node.telemetry.vel_ned_m_s

    @property
    def home_ned_m(self) -> Vec3:
        """This drone's launch point in the mission frame (its ``initial_positions`` entry)."""
        return self._node.home_ned_m

    @property
    def inferiors(self) -> Mapping[int, InferiorReport]:
        """Latest Report of each alive direct inferior, as delivered by the network."""
        return self._node.alive_reports()

    @property
    def peers(self) -> Mapping[int, PeerState]:
        """Latest Heartbeat (stage, position, velocity) of each peer this drone listens to."""
        return self._node.peer_view

    @property
    def last_task(self) -> Task | None:
        """The most recent task delivered (each one also goes to ``on_task``, in order)."""
        return self._node.last_task

    @property
    def proximity(self) -> tuple[DescendantState, ...]:
        """Drones the ground saw within ``run.proximity_m`` of this one (its latest ProxAlert).

        Empty once the ground sends its all-clear, or when no alert came for ``lost_inferior_ticks``.
        """
        return self._node.proximity

    @property
    def report_data(self) -> str:
        return self._node.report_data

    @report_data.setter
    def report_data(self, value: str) -> None:
        """Free-form payload carried by every following Report to the superior."""
        self._node.report_data = str(value)

    def has_reached(self, target_ned_m: Sequence[float], d_m: float = 0.7, v_m_s: float = 0.7) -> bool:
        """True when within ``d_m`` (3-D) of the target and slower than ``v_m_s``."""
        tel = self._node.telemetry
        p, v = tel.pos_ned_m, tel.vel_ned_m_s
        dist = math.dist(p, target_ned_m)
        return dist <= d_m and math.hypot(*v) <= v_m_s


@final
class GroundContext(_Context):
    """What the ground algorithm sees."""

    __slots__ = ()

    @property
    def reports(self) -> Mapping[int, InferiorReport]:
        """Latest Report of each alive direct inferior, as delivered by the network."""
        return self._node.alive_reports()

    @property
    def alive(self) -> frozenset[int]:
        """Direct inferiors currently heard from."""
        return frozenset(self._node.alive_reports())

    @property
    def swarm(self) -> Mapping[int, DescendantState]:
        """Every drone the ground knows of (direct inferiors and the descendants they forward)."""
        return self._node.swarm_view()

    @property
    def swarm_size(self) -> int:
        return self._node.mission.swarm_size
