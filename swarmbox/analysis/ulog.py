"""PX4's own flight logs (ULog) on the run's unified timeline.

A run on launched PX4 SITL instances leaves each instance's ULogs in ``px4/instance_<i>/`` and an
index ``logs/drone_<i>/ulog.json`` (written by :mod:`swarmbox.hal.px4.sitl`): the files in order, the
vehicle's boot clock (boot time -> that drone's clock, fitted by the bridge) and its home in the
mission frame. Parsing happens here, after the run, so the run itself never pays for it.

:func:`local_position` reads ``vehicle_local_position`` (PX4's EKF output) with ``t_s`` on the drone's
clock and ``pos_n/pos_e/pos_d`` in the mission frame, like the drone's ``state`` table;
:func:`estimator_resets` lists the EKF's position resets (``xy_reset_counter`` steps), the baseline a
fault analysis compares with.
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
