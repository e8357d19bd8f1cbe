"""Export a replay to MCAP, for Foxglove and PlotJuggler.

Topics (log time = the record's unified time, as absolute time from the run's start):

==========================  ========================  =============================================
topic                       encoding / schema         what
==========================  ========================  =============================================
``/drone_<i>/pose``         protobuf                  estimated pose, frame ``mission_enu``
                            ``foxglove.PoseInFrame``  (x east, y north, z up; yaw about z)
``/drone_<i>/state``        JSON                      the state row: NED estimate, GNSS, ground
                                                      truth, velocity, stage, armed, battery
``/drone_<i>/setpoint``     JSON                      kind, n/e/d (m, m/s or m/s²), yaw, verdict
``/drone_<i>/metrics``      JSON                      per bin: latency_ms, loss_ratio, disc_*_m
``/links``                  protobuf                  per bin: drones as spheres, every link as a
                            ``foxglove.SceneUpdate``  line coloured by latency (green -> red)
``/link/<src>_<dst>``       JSON                      per bin: latency_ms, loss_ratio, messages
``/stages``, ``/events``    protobuf ``foxglove.Log`` stage changes; markers, faults, safety, ...
==========================  ========================  =============================================

Protobuf schemas are Foxglove's own (``foxglove-schemas-protobuf``); JSON channels carry a JSON
Schema generated from their fields, so PlotJuggler can plot every number.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import register_schema

from swarmbox.analysis.replay import Replay, enu, latency_rgb, node_label
from swarmbox.analysis.unify import T

FRAME = "mission_enu"
STATE_FIELDS = ["stage", "armed", "landed", "pos_n", "pos_e", "pos_d", "vel_n", "vel_e", "vel_d",
                "gnss_n", "gnss_e", "gnss_d", "true_n", "true_e", "true_d", "yaw_rad", "battery_frac"]
SETPOINT_FIELDS = ["kind", "n", "e", "d", "yaw_rad", "verdict"]
_LEVEL = {"error": Log.ERROR, "failsafe": Log.ERROR, "collision": Log.ERROR, "safety": Log.WARNING,
          "fault": Log.WARNING, "proximity": Log.WARNING, "topology": Log.WARNING}


class _Mcap:
    """An MCAP writer with one channel per topic, registered on first use."""

    def __init__(self, stream: Any) -> None:
        self.writer = Writer(stream, compression=CompressionType.ZSTD)
        self.writer.start(profile="", library="swarmbox")
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}

    def proto(self, topic: str, t_ns: int, msg: Any) -> None:
        if topic not in self._channels:
            name = type(msg).DESCRIPTOR.full_name
            if name not in self._schemas:
                self._schemas[name] = register_schema(self.writer, type(msg))
            self._channels[topic] = self.writer.register_channel(topic, "protobuf", self._schemas[name])
        self.writer.add_message(self._channels[topic], int(t_ns), msg.SerializeToString(), int(t_ns))

    def json(self, topic: str, t_ns: int, record: dict[str, Any]) -> None:
        if topic not in self._channels:
            schema = {"type": "object", "properties": {k: _json_type(v) for k, v in record.items()}}
            sid = self.writer.register_schema(topic.strip("/").replace("/", "."), "jsonschema",
                                              json.dumps(schema).encode())
            self._channels[topic] = self.writer.register_channel(topic, "json", sid)
        self.writer.add_message(self._channels[topic], int(t_ns), json.dumps(record).encode(), int(t_ns))

    def finish(self) -> None:
        self.writer.finish()


def _json_type(value: Any) -> dict[str, str]:
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, int | float):
        return {"type": "number"}
    return {"type": "string"}


def _plain(value: Any) -> Any:
    """JSON-safe scalar (NaN -> None)."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _stamp(t_ns: int) -> Timestamp:
    return Timestamp(seconds=t_ns // 1_000_000_000, nanos=t_ns % 1_000_000_000)


def _yaw_quaternion(yaw_ned: float) -> Quaternion:
    """NED yaw (clockwise from north) -> rotation about ENU z (counter-clockwise from east)."""
    yaw = math.pi / 2 - (yaw_ned if math.isfinite(yaw_ned) else 0.0)
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _write_drones(out: _Mcap, rp: Replay) -> None:
    for drone, rows in rp.state.groupby("node", sort=True):
        xyz = enu(rows["pos_n"].to_numpy(), rows["pos_e"].to_numpy(), rows["pos_d"].to_numpy())
        times = rp.epoch_ns(rows[T].to_numpy())
        records = rows[STATE_FIELDS].to_dict("records")
        for t_ns, p, yaw, rec in zip(times, xyz, rows["yaw_rad"].to_numpy(), records, strict=True):
            out.proto(f"/drone_{drone}/pose", t_ns, PoseInFrame(
                timestamp=_stamp(int(t_ns)), frame_id=FRAME,
                pose=Pose(position=Vector3(x=p[0], y=p[1], z=p[2]), orientation=_yaw_quaternion(yaw))))
            out.json(f"/drone_{drone}/state", t_ns, {k: _plain(v) for k, v in rec.items()})
    for drone, rows in rp.setpoints.groupby("node", sort=True):
        for t_ns, rec in zip(rp.epoch_ns(rows[T].to_numpy()), rows[SETPOINT_FIELDS].to_dict("records"),
                             strict=True):
            out.json(f"/drone_{drone}/setpoint", t_ns, {k: _plain(v) for k, v in rec.items()})
    if len(rp.metrics):
        wide = rp.metrics.pivot_table(index=[T, "drone"], columns="metric", values="value").reset_index()
        for rec in wide.to_dict("records"):
            t_ns = int(rp.epoch_ns(rec.pop(T)))
            drone = int(rec.pop("drone"))
            out.json(f"/drone_{drone}/metrics", t_ns, {k: _plain(v) for k, v in rec.items()})


def _positions_at(rp: Replay, t_u: float) -> dict[int, np.ndarray]:
    """Each drone's latest ENU position at or before ``t_u``; the ground at the mission origin."""
    upto = rp.state[rp.state[T] <= t_u]
    last = upto.groupby("node").tail(1)
    pos = {int(r.node): enu(np.array([r.pos_n]), np.array([r.pos_e]), np.array([r.pos_d]))[0]
           for r in last.itertuples()}
    pos[-1] = np.zeros(3)
    return pos


def _write_links(out: _Mcap, rp: Replay) -> None:
    for t_u, rows in rp.links.groupby(T, sort=True):
        t_ns = int(rp.epoch_ns(t_u))
        where = _positions_at(rp, float(t_u))
        colors = latency_rgb(rows["latency_ms"].to_numpy())
        lines, spheres = [], []
        for (src, dst), rgb in zip(rows[["src", "dst"]].itertuples(index=False), colors, strict=True):
            a, b = where.get(int(src)), where.get(int(dst))
            if a is None or b is None:
                continue
            lines.append(LinePrimitive(
                type=LinePrimitive.LINE_LIST, thickness=0.1, scale_invariant=False,
                points=[Point3(x=a[0], y=a[1], z=a[2]), Point3(x=b[0], y=b[1], z=b[2])],
                color=Color(r=rgb[0], g=rgb[1], b=rgb[2], a=1.0)))
        for node, p in where.items():
            spheres.append(SpherePrimitive(pose=Pose(position=Vector3(x=p[0], y=p[1], z=p[2]),
                                                     orientation=Quaternion(w=1.0)),
                                           size=Vector3(x=0.6, y=0.6, z=0.6),
                                           color=Color(r=0.2, g=0.4, b=1.0, a=1.0) if node >= 0
                                           else Color(r=1.0, g=1.0, b=1.0, a=1.0)))
        out.proto("/links", t_ns, SceneUpdate(entities=[SceneEntity(
            timestamp=_stamp(t_ns), frame_id=FRAME, id="swarm", lines=lines, spheres=spheres)]))
        for rec in rows.to_dict("records"):
            out.json(f"/link/{node_label(int(rec['src']))}_{node_label(int(rec['dst']))}", t_ns,
                     {"latency_ms": _plain(rec["latency_ms"]), "loss_ratio": _plain(rec["loss_ratio"]),
                      "messages": int(rec["messages"])})


def _write_logs(out: _Mcap, rp: Replay) -> None:
    for rec in rp.stages.to_dict("records"):
        t_ns = int(rp.epoch_ns(rec[T]))
        reason = f": {rec['reason']}" if rec["reason"] else ""
        level = Log.ERROR if rec["stage"] < 0 else Log.INFO
        out.proto("/stages", t_ns, Log(timestamp=_stamp(t_ns), level=level, name=node_label(int(rec["node"])),
                                       message=f"{rec['name']}{reason}"))
    for rec in rp.events.to_dict("records"):
        t_ns = int(rp.epoch_ns(rec[T]))
        out.proto("/events", t_ns, Log(timestamp=_stamp(t_ns), level=_LEVEL.get(rec["kind"], Log.INFO),
                                       name=node_label(int(rec["node"])),
                                       message=f"{rec['kind']}/{rec['name']} subject={rec['subject']} "
                                               f"{rec['data']}"))


def export_mcap(rp: Replay, path: str | Path) -> Path:
    """Write the replay to ``path`` (written beside it first, then renamed: never half a file)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial")
    with open(tmp, "wb") as stream:
        out = _Mcap(stream)
        out.writer.add_metadata("swarmbox", {"run": str(rp.run_dir), "span_s": json.dumps(list(rp.span)),
                                             "frame": FRAME, "frame_note": "x east, y north, z up"})
        _write_drones(out, rp)
        _write_links(out, rp)
        _write_logs(out, rp)
        out.finish()
    tmp.replace(path)
    return path
