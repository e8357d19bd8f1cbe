"""Tiny synthetic run directories with exactly known metrics, written as real Parquet files.

A :class:`Scenario` describes a star (or hierarchical) swarm on a 25 ms tick: the ground sends one
Heartbeat per tick to each direct inferior, each drone sends one Report per tick to its superior and
a Heartbeat to its own inferiors. A message sent at tick k arrives at tick
``k + delay_ticks + extra(src) + extra(dst)``; arrivals at or past the last tick are never logged (in
flight). Every node writes its own local clock ``offset + (1 + drift) * t``. Drone i hovers at
(0, spacing*i, -10) and, during EXECUTION, flies north at ``speeds_m_s[i]`` (and climbs at
``climb_m_s``) until its completion tick, then hovers again.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
import yaml

from swarmbox.record.schema import NO_SUBJECT, SCHEMA_VERSION, TABLES, node_name

TICK_S = 0.025
STAGE_NAMES = {-1: "ABORT", 1: "ICEBREAK", 2: "PREPARATION", 3: "EXECUTION", 4: "LANDING", 5: "TERMINATION"}
_ARROW = {"float64": pa.float64(), "int64": pa.int64(), "int32": pa.int32(), "int16": pa.int16(),
          "int8": pa.int8(), "bool": pa.bool_(), "string": pa.string()}


@dataclass
class Scenario:
    n_drones: int = 4
    ticks: int = 800
    ground_stages: dict[int, int] = field(default_factory=lambda: {1: 0, 2: 40, 3: 80, 4: 680, 5: 760})
    speeds_m_s: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0)
    complete_ticks: dict[int, int] = field(default_factory=lambda: {0: 280, 1: 480, 2: 380})
    climb_m_s: dict[int, float] = field(default_factory=dict)
    spacing_m: float = 5.0
    clocks: dict[str, tuple[float, float]] = field(default_factory=dict)   # node -> (offset_s, drift_ppm)
    delay_ticks: int = 1
    extra_delay_ticks: dict[int, int] = field(default_factory=dict)
    drop_every: dict[int, int] = field(default_factory=dict)   # drone -> every k-th Report lost
    superiors: dict[int, int] = field(default_factory=dict)    # default -1 (the ground)
    gnss_drift: tuple[int, int, float] | None = None           # (drone, start tick, north m/s)
    gnss_bias_m: dict[int, float] = field(default_factory=dict)  # constant north GNSS bias per drone
    fault: tuple[str, int, int] | None = None                  # (fault name, tick, target)
    markers: list[tuple[int, int, str, dict]] = field(default_factory=list)  # (node, tick, name, data)
    collisions: list[tuple[int, int]] = field(default_factory=list)          # (drone, tick)
    progress: list[tuple[int, int, str]] = field(default_factory=list)       # extra progress events
    status: str = "ok"
    seed: int = 0
    choices: dict[str, str] = field(default_factory=lambda: {"algo": "synthetic", "mission": "synthetic"})
    algo_metrics: list[dict[str, Any]] = field(default_factory=list)
    skip_files: tuple[str, ...] = ()    # e.g. ("drone_1/state",) to simulate a partial run

    def superior(self, drone: int) -> int:
        return self.superiors.get(drone, -1)

    def local(self, node: int, tick: int) -> float:
        offset, drift_ppm = self.clocks.get(node_name(node), (0.0, 0.0))
        t = tick * TICK_S
        return offset + (1.0 + drift_ppm * 1e-6) * t

    def arrival(self, src: int, dst: int, tick: int) -> int:
        extra = self.extra_delay_ticks
        return tick + self.delay_ticks + extra.get(src, 0) + extra.get(dst, 0)

    def stage_at(self, tick: int, lag: int = 0) -> int:
        entered = [s for s, k in self.ground_stages.items() if k + lag <= tick]
        return max(entered, key=lambda s: self.ground_stages[s]) if entered else 1

    def exec_tick(self) -> int:
        return self.ground_stages.get(3, self.ticks)


Vec3 = tuple[float, float, float]


def _pose(sc: Scenario, drone: int, tick: int) -> tuple[Vec3, Vec3]:
    start = sc.exec_tick()
    stop = sc.complete_ticks.get(drone, sc.ground_stages.get(4, sc.ticks))
    moving_ticks = min(max(tick - start, 0), max(stop - start, 0))
    speed, climb = sc.speeds_m_s[drone], sc.climb_m_s.get(drone, 0.0)
    t = moving_ticks * TICK_S
    pos = (speed * t, sc.spacing_m * drone, -10.0 - climb * t)
    moving = start <= tick < stop
    vel = (speed, 0.0, -climb) if moving else (0.0, 0.0, 0.0)
    return pos, vel


def _state_rows(sc: Scenario, drone: int) -> list[dict]:
    rows = []
    for k in range(sc.ticks):
        (n, e, d), (vn, ve, vd) = _pose(sc, drone, k)
        gnss_n = n + sc.gnss_bias_m.get(drone, 0.0)
        if sc.gnss_drift and sc.gnss_drift[0] == drone and k >= sc.gnss_drift[1]:
            gnss_n += sc.gnss_drift[2] * (k - sc.gnss_drift[1]) * TICK_S
        rows.append({
            "t_s": sc.local(drone, k), "tick": k, "stage": sc.stage_at(k, lag=1), "armed": True,
            "landed": False, "mode": "offboard", "pos_n": n, "pos_e": e, "pos_d": d,
            "vel_n": vn, "vel_e": ve, "vel_d": vd, "gnss_n": gnss_n, "gnss_e": e, "gnss_d": d,
            "true_n": n, "true_e": e, "true_d": d, "yaw_rad": 0.0, "battery_frac": 1.0,
        })
    return rows


def _message_rows(sc: Scenario) -> dict[int, list[dict]]:
    """Messages tables of every node (ground -1, drones, net -2)."""
    out: dict[int, list[dict]] = defaultdict(list)
    msg_seq = 0
    reports_sent: dict[int, int] = defaultdict(int)
    inferiors: dict[int, list[int]] = defaultdict(list)
    for d in range(sc.n_drones):
        inferiors[sc.superior(d)].append(d)

    def emit(src: int, dsts: list[int], tick: int, mtype: str, nbytes: int, dropped: bool = False) -> None:
        nonlocal msg_seq
        msg_seq += 1
        t_sent = sc.local(src, tick)
        for dst in dsts:
            base = {"msg_id": msg_seq, "type": mtype, "src": src, "dst": dst, "nbytes": nbytes,
                    "t_sent_s": t_sent, "reason": ""}
            out[src].append({"t_s": t_sent, "tick": tick, "kind": "send", **base})
            arrive = sc.arrival(src, dst, tick)
            if dropped:
                out[-2].append({"t_s": tick * TICK_S, "tick": tick, "kind": "drop", **base, "reason": "loss"})
            elif arrive < sc.ticks:
                out[dst].append({"t_s": sc.local(dst, arrive), "tick": arrive, "kind": "recv", **base})

    for k in range(sc.ticks):
        for node in sorted(inferiors):
            emit(node, inferiors[node], k, "heartbeat", 50)
        for d in range(sc.n_drones):
            reports_sent[d] += 1
            every = sc.drop_every.get(d)
            emit(d, [sc.superior(d)], k, "report", 100, dropped=bool(every) and reports_sent[d] % every == 0)
    return out


def _stage_rows(sc: Scenario, node: int) -> list[dict]:
    lag = 0 if node == -1 else 1
    entries = sorted(sc.ground_stages.items(), key=lambda x: x[1])
    return [{"t_s": sc.local(node, k + lag), "tick": k + lag, "stage": s, "name": STAGE_NAMES[s],
             "reason": ""} for s, k in entries if k + lag < sc.ticks]


def _event(sc: Scenario, node: int, tick: int, kind: str, name: str, subject: int, data: dict) -> dict:
    return {"t_s": sc.local(node, tick), "tick": tick, "kind": kind, "name": name, "subject": subject,
            "data": json.dumps(data)}


def _event_rows(sc: Scenario) -> dict[int, list[dict]]:
    out: dict[int, list[dict]] = defaultdict(list)
    for drone, tick in sc.complete_ticks.items():
        out[drone].append(_event(sc, drone, tick, "progress", "exec_complete", drone, {}))
    for drone, tick, name in sc.progress:
        out[drone].append(_event(sc, drone, tick, "progress", name, drone, {}))
    for node, tick, name, data in sc.markers:
        out[node].append(_event(sc, node, tick, "marker", name, NO_SUBJECT, data))
    for drone, tick in sc.collisions:
        out[drone].append(_event(sc, drone, tick, "collision", "contact", drone, {}))
    if sc.fault:
        name, tick, target = sc.fault
        out[-1].append(_event(sc, -1, tick, "fault", f"{name}_start", target, {"target": target}))
    return out


def write_table(path: Path, table: str, rows: list[dict]) -> None:
    """Write rows as a Parquet file with the schema's column types and version metadata."""
    cols = TABLES[table]
    schema = pa.schema([(c.name, _ARROW[c.dtype]) for c in cols],
                       metadata={"swarmbox.schema": SCHEMA_VERSION})
    arrays = {c.name: [r[c.name] for r in rows] for c in cols}
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pydict(arrays, schema=schema), path)


def manifest(sc: Scenario) -> dict[str, Any]:
    nodes = ["ground"] + [f"drone_{i}" for i in range(sc.n_drones)] + ["net"]
    return {
        "schema": "1", "status": sc.status, "reason": "", "traceback": None, "seed": sc.seed,
        "choices": {**{"topology": "centralized", "backend": "sim", "network": "ideal", "fault": "none"},
                    **sc.choices},
        "overrides": [f"seed={sc.seed}"], "sim_time_s": sc.ticks * TICK_S,
        "wall_time_s": sc.ticks * TICK_S / 100, "real_time_factor": 100.0, "ticks": sc.ticks,
        "tick_s": TICK_S, "n_drones": sc.n_drones, "nodes": nodes,
        "clocks": {k: {"offset_s": o, "drift_ppm": d} for k, (o, d) in sc.clocks.items()},
        "versions": {}, "git_sha": "0" * 40, "started_at": "2026-01-01T00:00:00",
    }


def build_run(run_dir: Path, sc: Scenario | None = None) -> Path:
    """Write a complete run directory for ``sc`` and return its path."""
    sc = sc or Scenario()
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run.json").write_text(json.dumps(manifest(sc), indent=1))
    config = {"seed": sc.seed, "algo": {"name": sc.choices.get("algo"), "metrics": sc.algo_metrics},
              "mission": {}, "topology": {}, "backend": {}, "network": {}, "fault": {}, "run": {}}
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config))
    messages, events = _message_rows(sc), _event_rows(sc)
    tables: dict[int, dict[str, list[dict]]] = {-1: {}, -2: {}}
    tables[-1] = {"messages": messages[-1], "stages": _stage_rows(sc, -1), "events": events[-1]}
    tables[-2] = {"messages": messages[-2]}
    for d in range(sc.n_drones):
        tables[d] = {"state": _state_rows(sc, d), "messages": messages[d], "stages": _stage_rows(sc, d),
                     "events": events[d], "setpoints": []}
    for node, node_tables in tables.items():
        for table, rows in node_tables.items():
            if f"{node_name(node)}/{table}" not in sc.skip_files:
                write_table(run_dir / "logs" / node_name(node) / f"{table}.parquet", table, rows)
    return run_dir
