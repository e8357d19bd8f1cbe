"""Export a replay to a Rerun recording (``.rrd``), for the Rerun viewer.

Two timelines: ``time`` (absolute, from the run's start) and ``run_time`` (unified seconds since the
run started). Entities (3-D in ENU: x east, y north, z up):

- ``world/drones/<i>``: the drone's estimated position at every state sample;
- ``world/trajectories/<i>``: the whole estimated path (static), ``world/truth/<i>`` the ground
  truth path when a simulator logged it;
- ``world/setpoints/<i>``: position setpoints;
- ``world/links/<src>_<dst>``: per bin, the link as a line coloured by its latency (green -> red,
  grey: nothing delivered); ``world/ground``: the ground station at the mission origin;
- ``stages``, ``events``: text logs (warnings for faults, safety, proximity; errors for failsafes);
- ``metrics/<metric>/drone_<i>``: the analyzer's per-drone series; ``links/latency_ms/<src>_<dst>``
  and ``links/loss_ratio/<src>_<dst>``: per-link series.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from swarmbox.analysis.replay import Replay, enu, latency_rgb, node_label
from swarmbox.analysis.unify import T

_LEVEL = {"error": "ERROR", "failsafe": "ERROR", "collision": "ERROR", "safety": "WARN", "fault": "WARN",
          "proximity": "WARN", "topology": "WARN"}


def _indexes(rp: Replay, t_u: np.ndarray) -> list[rr.TimeColumn]:
    t_u = np.asarray(t_u, dtype="float64")
    return [rr.TimeColumn("time", timestamp=rp.epoch_ns(t_u).astype("datetime64[ns]")),
            rr.TimeColumn("run_time", duration=t_u)]


def _colour(drone: int) -> np.ndarray:
    palette = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
                        [140, 86, 75], [227, 119, 194], [127, 127, 127], [188, 189, 34], [23, 190, 207]])
    return palette[drone % len(palette)].astype("uint8")


def _drones(rec: rr.RecordingStream, rp: Replay) -> None:
    for drone, rows in rp.state.groupby("node", sort=True):
        drone = int(drone)
        xyz = enu(rows["pos_n"].to_numpy(), rows["pos_e"].to_numpy(), rows["pos_d"].to_numpy())
        rec.send_columns(f"world/drones/{drone}", indexes=_indexes(rp, rows[T].to_numpy()),
                         columns=rr.Points3D.columns(positions=xyz))
        rec.log(f"world/drones/{drone}", rr.Points3D.from_fields(radii=0.3, colors=_colour(drone),
                                                                 labels=f"drone {drone}"), static=True)
        rec.log(f"world/trajectories/{drone}", rr.LineStrips3D([xyz], colors=_colour(drone), radii=0.05),
                static=True)
        truth = rows[["true_n", "true_e", "true_d"]].dropna()
        if len(truth):
            rec.log(f"world/truth/{drone}", rr.LineStrips3D(
                [enu(truth["true_n"].to_numpy(), truth["true_e"].to_numpy(), truth["true_d"].to_numpy())],
                colors=[200, 200, 200], radii=0.02), static=True)
    for drone, rows in rp.setpoints[rp.setpoints["kind"] == "position"].groupby("node", sort=True):
        rec.send_columns(f"world/setpoints/{int(drone)}", indexes=_indexes(rp, rows[T].to_numpy()),
                         columns=rr.Points3D.columns(positions=enu(rows["n"].to_numpy(), rows["e"].to_numpy(),
                                                                   rows["d"].to_numpy())))
    rec.log("world/ground", rr.Points3D([[0.0, 0.0, 0.0]], radii=0.5, colors=[255, 255, 255],
                                        labels="ground"), static=True)


def _links(rec: rr.RecordingStream, rp: Replay) -> None:
    if rp.links.empty:
        return
    state = rp.state.sort_values(T)
    for (src, dst), rows in rp.links.groupby(["src", "dst"], sort=True):
        ends = [_track(state, int(node), rows[T].to_numpy()) for node in (src, dst)]
        strips = np.stack(ends, axis=1)                      # (bins, 2, 3)
        keep = ~np.isnan(strips).any(axis=(1, 2))
        name = f"{node_label(int(src))}_{node_label(int(dst))}"
        t_u = rows[T].to_numpy()
        if keep.any():
            colours = (latency_rgb(rows["latency_ms"].to_numpy()[keep]) * 255).astype("uint8")
            rec.send_columns(f"world/links/{name}", indexes=_indexes(rp, t_u[keep]),
                             columns=rr.LineStrips3D.columns(strips=list(strips[keep]), colors=colours))
        for metric in ("latency_ms", "loss_ratio"):
            values = rows[metric].to_numpy(dtype="float64")
            ok = np.isfinite(values)
            if ok.any():
                rec.send_columns(f"links/{metric}/{name}", indexes=_indexes(rp, t_u[ok]),
                                 columns=rr.Scalars.columns(scalars=values[ok]))


def _track(state, node: int, t_u: np.ndarray) -> np.ndarray:
    """ENU position of ``node`` at each time (latest sample before it); the ground at the origin."""
    if node < 0:
        return np.zeros((len(t_u), 3))
    rows = state[state["node"] == node]
    if rows.empty:
        return np.full((len(t_u), 3), np.nan)
    idx = np.searchsorted(rows[T].to_numpy(), t_u, side="right") - 1
    xyz = enu(rows["pos_n"].to_numpy(), rows["pos_e"].to_numpy(), rows["pos_d"].to_numpy())
    out = xyz[np.clip(idx, 0, len(rows) - 1)]
    out[idx < 0] = np.nan
    return out


def _logs(rec: rr.RecordingStream, rp: Replay) -> None:
    if len(rp.stages):
        st = rp.stages
        text = [f"{node_label(int(n))}: {name}" + (f" ({why})" if why else "")
                for n, name, why in zip(st["node"], st["name"], st["reason"], strict=True)]
        level = ["ERROR" if s < 0 else "INFO" for s in st["stage"]]
        rec.send_columns("stages", indexes=_indexes(rp, st[T].to_numpy()),
                         columns=rr.TextLog.columns(text=text, level=level))
    if len(rp.events):
        ev = rp.events
        text = [f"{node_label(int(n))}: {k}/{name} subject={s} {d}"
                for n, k, name, s, d in zip(ev["node"], ev["kind"], ev["name"], ev["subject"], ev["data"],
                                            strict=True)]
        level = [_LEVEL.get(k, "INFO") for k in ev["kind"]]
        rec.send_columns("events", indexes=_indexes(rp, ev[T].to_numpy()),
                         columns=rr.TextLog.columns(text=text, level=level))


def _metrics(rec: rr.RecordingStream, rp: Replay) -> None:
    for (metric, drone), rows in rp.metrics.groupby(["metric", "drone"], sort=True):
        rec.send_columns(f"metrics/{metric}/drone_{int(drone)}", indexes=_indexes(rp, rows[T].to_numpy()),
                         columns=rr.Scalars.columns(scalars=rows["value"].to_numpy(dtype="float64")))


def _layout() -> rrb.Blueprint:
    """The swarm in 3-D beside the link and metric series and the event log."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="swarm (ENU)"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="metrics/latency_ms", name="latency (ms) per drone"),
                rrb.TimeSeriesView(origin="metrics/loss_ratio", name="loss ratio per drone"),
                rrb.TimeSeriesView(origin="metrics/disc_n_m", name="GNSS - estimate, north (m)"),
                rrb.TextLogView(origin="/", contents=["stages", "events"], name="stages and events"),
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="run_time"),
        collapse_panels=True,
    )


def export_rerun(rp: Replay, path: str | Path) -> Path:
    """Write the replay as a Rerun recording (written beside ``path`` first, then renamed)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial")
    rec = rr.RecordingStream("swarmbox", recording_id=f"{rp.name}-{rp.span[0]:.3f}-{rp.span[1]:.3f}")
    rec.save(tmp, default_blueprint=_layout())
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _drones(rec, rp)
    _links(rec, rp)
    _logs(rec, rp)
    _metrics(rec, rp)
    rec.flush()
    rec.disconnect()
    tmp.replace(path)
    return path
