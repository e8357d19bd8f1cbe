"""PX4's own flight logs (ULog) on the run's unified timeline.

A run on launched PX4 SITL instances leaves each instance's ULogs in ``px4/instance_<i>/`` and an
index ``logs/drone_<i>/ulog.json`` (written by :mod:`swarmbox.hal.px4.sitl`): the files in order, the
vehicle's boot clock (boot time -> that drone's clock, fitted by the bridge) and its home in the
mission frame. Parsing happens here, after the run, so the run itself never pays for it.

:func:`local_position` reads ``vehicle_local_position`` (PX4's EKF output) with ``t_s`` on the drone's
clock and ``pos_n/pos_e/pos_d`` in the mission frame, like the drone's ``state`` table;
:func:`estimator_resets` lists the EKF's position resets (``xy_reset_counter`` steps), the baseline a
fault analysis compares with.

:func:`estimator_events` turns EKF2's own markers into ``estimator`` events of the drone (the same
kind the ``sim`` backend's estimator logs): ``position_reset`` (a horizontal position reset),
``dead_reckoning`` (EKF2 left without a horizontal aiding source, ``cs_inertial_dead_reckoning``
rising: a GNSS loss is seen here first), ``gnss_fusion_lost`` / ``gnss_fusion_regained``
(``cs_gnss_pos``) and ``gnss_fix_lost`` / ``gnss_fix_regained`` (the receiver's ``fix_type``
crossing 3D). :func:`add_estimator_events` appends them to a loaded run's ``events`` table on each
drone's clock, so the analyzer's unification puts them on the run's timeline with everything else
and the per-drone estimator baseline reads PX4's own log.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

INDEX = "ulog.json"
_FIELDS = (("x", "x_m"), ("y", "y_m"), ("z", "z_m"), ("vx", "vx_m_s"), ("vy", "vy_m_s"),
           ("vz", "vz_m_s"), ("heading", "heading_rad"))
_FLAGS = ("xy_valid", "z_valid")
_COUNTERS = ("xy_reset_counter", "z_reset_counter")


def ulog_index(run_dir: Path, drone: int) -> dict[str, Any] | None:
    """The drone's ``ulog.json`` (None when the run kept no ULog for it)."""
    path = Path(run_dir) / "logs" / f"drone_{drone}" / INDEX
    if not path.is_file():
        return None
    return json.loads(path.read_text())


def _boot_to_drone(clock: dict[str, float], boot_s: np.ndarray) -> np.ndarray:
    return (clock["a"] + clock["b"] * boot_s) * clock["scale"] + clock["offset_s"]


def local_position(run_dir: Path, drone: int) -> pd.DataFrame:
    """``vehicle_local_position`` of the drone's ULogs on its clock (empty frame if there is none)."""
    from pyulog import ULog

    index = ulog_index(run_dir, drone)
    if index is None:
        return pd.DataFrame()
    base = Path(run_dir) / "logs" / f"drone_{drone}"
    home = index["home_ned_m"]
    parts = []
    for name in index["files"]:
        ulog = ULog(str(base / name), ["vehicle_local_position"])
        for data in ulog.data_list:
            if data.name != "vehicle_local_position" or data.multi_id != 0:
                continue
            d = data.data
            stamp = d["timestamp"].astype(np.int64)
            cols: dict[str, Any] = {"t_s": _boot_to_drone(index["clock"], stamp / 1e6),
                                    "px4_timestamp_us": stamp}
            for src, dst in _FIELDS:
                cols[dst] = d[src].astype(np.float64) if src in d else np.full(len(stamp), np.nan)
            for k, axis in enumerate(("pos_n", "pos_e", "pos_d")):
                cols[axis] = cols[("x_m", "y_m", "z_m")[k]] + home[k]
            for flag in _FLAGS:
                cols[flag] = d[flag].astype(bool) if flag in d else np.zeros(len(stamp), dtype=bool)
            for counter in _COUNTERS:
                zeros = np.zeros(len(stamp), np.int64)
                cols[counter] = d[counter].astype(np.int64) if counter in d else zeros
            cols["ulog_file"] = Path(name).name
            parts.append(pd.DataFrame(cols))
    if not parts:
        return pd.DataFrame()
    return pd.concat(parts, ignore_index=True)


def estimator_resets(run_dir: Path, drone: int) -> pd.DataFrame:
    """The EKF's horizontal position resets in the drone's ULog: ``t_s`` (drone clock) and ``count``."""
    pos = local_position(run_dir, drone)
    if pos.empty:
        return pd.DataFrame({"t_s": [], "count": []})
    steps = pos["xy_reset_counter"].diff().fillna(0) != 0
    return pd.DataFrame({"t_s": pos.loc[steps, "t_s"].to_numpy(),
                         "count": pos.loc[steps, "xy_reset_counter"].to_numpy()})


#: (topic, field, event when it turns on, event when it turns off); None: not an event
_MARKERS = (("estimator_status_flags", "cs_inertial_dead_reckoning", "dead_reckoning", None),
            ("estimator_status_flags", "cs_gnss_pos", "gnss_fusion_regained", "gnss_fusion_lost"),
            ("sensor_gps", "fix_type", "gnss_fix_regained", "gnss_fix_lost"))
FIX_3D = 3


def _marker_rows(ulog: Any, clock: dict[str, float]) -> list[tuple[float, str, dict[str, Any]]]:
    """Transitions of EKF2's flags and the receiver's fix in one ULog (the first sample is the
    initial state, not an event)."""
    rows = []
    for data in ulog.data_list:
        if data.multi_id != 0:
            continue
        for topic, field, on, off in _MARKERS:
            if data.name != topic or field not in data.data:
                continue
            raw = data.data[field].astype(np.int64)
            state = raw >= FIX_3D if field == "fix_type" else raw != 0
            t = _boot_to_drone(clock, data.data["timestamp"].astype(np.int64) / 1e6)
            for k in np.nonzero(np.diff(state.astype(np.int8)))[0] + 1:
                name = on if state[k] else off
                if name is not None:
                    rows.append((float(t[k]), name, {"source": f"{topic}.{field}", "value": int(raw[k])}))
    return rows


def estimator_events(run_dir: Path, drone: int) -> pd.DataFrame:
    """EKF2's markers and position resets in the drone's ULogs as ``estimator`` events: columns
    ``t_s`` (drone clock), ``name``, ``data`` (JSON); empty when the run kept no ULog for it."""
    from pyulog import ULog

    index = ulog_index(run_dir, drone)
    rows: list[tuple[float, str, dict[str, Any]]] = []
    if index is not None:
        base = Path(run_dir) / "logs" / f"drone_{drone}"
        for name in index["files"]:
            ulog = ULog(str(base / name), sorted({m[0] for m in _MARKERS}))
            rows.extend(_marker_rows(ulog, index["clock"]))
        resets = estimator_resets(run_dir, drone)
        rows.extend((float(t), "position_reset", {"count": int(c), "source": "vehicle_local_position"})
                    for t, c in zip(resets["t_s"], resets["count"], strict=True))
    rows.sort(key=lambda r: r[0])
    return pd.DataFrame({"t_s": [r[0] for r in rows], "name": [r[1] for r in rows],
                         "data": [json.dumps(r[2], sort_keys=True) for r in rows]})


def add_estimator_events(run_dir: Path, events: pd.DataFrame,
                         state: pd.DataFrame | None = None) -> pd.DataFrame:
    """``events`` with every drone's :func:`estimator_events` appended (node = subject = the drone,
    ``tick`` interpolated from the drone's ``state`` table); unchanged when no drone has a ULog."""
    parts = [events]
    for index in sorted(Path(run_dir).glob(f"logs/drone_*/{INDEX}")):
        drone = int(index.parent.name.split("_")[1])
        ev = estimator_events(run_dir, drone)
        if ev.empty:
            continue
        ticks = np.zeros(len(ev), np.int64)
        if state is not None and len(state) and "tick" in state:
            mine = state[state["node"] == drone].sort_values("t_s")
            if len(mine):
                ticks = np.rint(np.interp(ev["t_s"], mine["t_s"], mine["tick"])).astype(np.int64)
        parts.append(pd.DataFrame({"t_s": ev["t_s"], "tick": ticks, "kind": "estimator", "name": ev["name"],
                                   "subject": drone, "data": ev["data"], "node": drone}))
    if len(parts) == 1:
        return events
    out = pd.concat(parts, ignore_index=True)
    return out.astype(events.dtypes.to_dict()).sort_values(["node", "t_s"], kind="stable", ignore_index=True)


def write_tables(run_dir: Path) -> list[Path]:
    """``logs/drone_<i>/ulog_local_position.parquet`` for every drone with ULogs (atomic writes)."""
    out = []
    for index in sorted(Path(run_dir).glob(f"logs/drone_*/{INDEX}")):
        drone = int(index.parent.name.split("_")[1])
        table = local_position(run_dir, drone)
        if table.empty:
            continue
        path = index.parent / "ulog_local_position.parquet"
        tmp = path.with_name(f".{path.name}.tmp")
        table.to_parquet(tmp, index=False)
        tmp.replace(path)
        out.append(path)
    return out
