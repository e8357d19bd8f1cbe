"""Stream a run live to a Rerun viewer (or an ``.rrd`` file) from the monitor's snapshots.

``run.rerun=rerun+http://127.0.0.1:9876/proxy`` sends to a viewer started with ``rerun``;
``run.rerun=live.rrd`` writes the stream to ``<run dir>/live.rrd``. Like the dashboard, it reads only
the ground's snapshots and logged events, on the monitor thread: drones' reported positions, the
ground's link to each drone as a line (green alive, red lost), per-drone Report latency and loss,
stages and events.
The full-detail replay of a finished run is ``python -m swarmbox.export`` (docs/monitor.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from swarmbox.monitor.feed import Snapshot
from swarmbox.monitor.targets import VIEWER_SCHEMES
from swarmbox.monitor.view import DashboardView


def _enu(ned: tuple[float, float, float]) -> list[float]:
    return [ned[1], ned[0], -ned[2]]


class RerunStream:
    """One recording fed from the monitor thread."""

    def __init__(self, target: str, name: str) -> None:
        self.rec = rr.RecordingStream("swarmbox", recording_id=f"live-{name}")
        if target.startswith(VIEWER_SCHEMES):
            self.rec.connect_grpc(target)
        else:
            Path(target).parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(target)
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.rec.log("world/ground", rr.Points3D([[0.0, 0.0, 0.0]], radii=0.5, labels="ground"), static=True)
        self.frames = 0

    def event(self, t_s: float, text: str, level: str = "INFO") -> None:
        self.rec.set_time("run_time", duration=t_s)
        self.rec.log("events", rr.TextLog(text, level=level))

    def snapshot(self, snap: Snapshot, view: DashboardView) -> None:
        rec = self.rec
        rec.set_time("run_time", duration=snap.t_s)
        for row in snap.drones:
            p = _enu(row.report.pos_ned_m)
            colour = [60, 200, 60] if row.alive else [220, 40, 40]
            rec.log(f"world/drones/{row.drone_id}", rr.Points3D([p], radii=0.3, colors=[colour],
                                                                 labels=f"drone {row.drone_id}"))
            rec.log(f"world/links/ground_drone_{row.drone_id}",
                    rr.LineStrips3D([[[0.0, 0.0, 0.0], p]], colors=[colour], radii=0.04))
            lat, loss = view.latency_ms(row.drone_id), view.loss(row.drone_id)
            if lat is not None:
                rec.log(f"metrics/latency_ms/drone_{row.drone_id}", rr.Scalars(lat))
            if loss is not None:
                rec.log(f"metrics/loss_ratio/drone_{row.drone_id}", rr.Scalars(loss))
        for fw in snap.forwarded:
            rec.log(f"world/drones/{fw.drone_id}", rr.Points3D([_enu(fw.pos_ned_m)], radii=0.3,
                                                                labels=f"drone {fw.drone_id}"))
        if snap.prox:
            where = {r.drone_id: _enu(r.report.pos_ned_m) for r in snap.drones}
            where |= {f.drone_id: _enu(f.pos_ned_m) for f in snap.forwarded}
            strips = [np.array([where[a], where[b]]) for (a, b), _ in snap.prox if a in where and b in where]
            rec.log("world/proximity", rr.LineStrips3D(strips, colors=[[255, 200, 0]], radii=0.08))
        else:
            rec.log("world/proximity", rr.Clear(recursive=False))
        self.frames += 1

    def close(self) -> Any:
        self.rec.flush()
        self.rec.disconnect()
        return self.frames
