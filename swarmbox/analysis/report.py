"""One run, end to end: load -> unify -> metrics -> timeline -> anomalies -> diagnosis.

Two diagnoses, kept apart: the *finding* (:mod:`.diagnosis`: the first alarm of the onset-agnostic
scan, drone, metric and time, with every alarm episode) is made for every run from its logs alone,
fault events or not; the onset-based table (:func:`.anomaly.diagnose`: t_f, tau_d, Sigma_a against a
fault onset) exists only when a truth does (a fault event, or an onset given), and is written as
*scoring*: it grades against that truth, it does not find anything by itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from swarmbox.analysis import anomaly, flowstream, metrics, mission, network, sampling
from swarmbox.analysis import diagnosis as dg
from swarmbox.analysis.catalog import Direction
from swarmbox.analysis.load import RunData, load_run
from swarmbox.analysis.timeline import drone_timeline
from swarmbox.analysis.unify import ClockOptions, T, unify

#: The columns a run analysis reads, for tables it does not read whole (``load_run(columns=...)``):
#: the setpoints only bound the run's time span and the messages' tick is never used; of the state,
#: time, tick and the positions and velocities (its stage, mode, flags, yaw and battery feed no table
#: and no figure: about a fifth of the state's memory). At 1,000 drones the rest of those tables is
#: about 300 MB a minute that would be loaded for nothing.
ANALYZED_COLUMNS: dict[str, tuple[str, ...]] = {
    "setpoints": ("t_s",),
    "state": ("t_s", "tick", *(f"{kind}_{axis}" for kind in ("pos", "vel", "gnss", "true")
                               for axis in "ned")),
    "messages": ("t_s", "kind", "msg_id", "type", "src", "dst", "nbytes", "t_sent_s", "reason"),
}
#: What the scalars alone read (a sweep): of the messages, all but the type.
SCALAR_COLUMNS: dict[str, tuple[str, ...]] = {
    **ANALYZED_COLUMNS,
    "messages": tuple(c for c in ANALYZED_COLUMNS["messages"] if c != "type"),
}


@dataclass(frozen=True)
class AnalysisOptions:
    """Knobs of a run analysis (defaults are the documented ones)."""

    window_s: float = 0.5              # timeline / anomaly window
    graph_window_s: float = 1.0        # communication-graph window
    clock: ClockOptions = field(default_factory=ClockOptions)
    separation_m: float = 2.0          # threshold of time_below_separation_s
    iqr_k: float = 1.5
    min_deviation: dict[str, float] = field(default_factory=dict)   # overrides per monitored metric
    fault_onset_u: float | None = None  # overrides the fault event (unified time, s)
    fault_target: int | None = None
    #: Compute only what the scalars need (a sweep reads nothing else): the links, the markers and,
    #: when there is no fault onset, the timeline and the flags are left empty, the agents (and
    #: drones) get only their tx/rx rates, not their latency and loss, and the messages no
    #: ``t_sent_u``. Same scalars.
    scalars_only: bool = False

    def tests(self) -> dict[str, anomaly.OutlierTest]:
        return anomaly.default_tests(self.iqr_k, self.min_deviation)


@dataclass
class RunAnalysis:
    """Every table and scalar computed for one run (with :attr:`AnalysisOptions.scalars_only`, some
    tables are empty or partial)."""

    run: RunData
    clocks: pd.DataFrame
    window: metrics.ExecWindow | None
    flow: pd.DataFrame
    links: pd.DataFrame
    agents: pd.DataFrame
    drones: pd.DataFrame
    timeline: pd.DataFrame
    swarm: pd.DataFrame
    connectivity: pd.DataFrame
    flags: pd.DataFrame
    diagnosis: pd.DataFrame   # onset-based scoring (empty without a fault onset)
    markers: pd.DataFrame
    onset: anomaly.FaultOnset | None
    scalars: dict[str, float]
    directions: dict[str, Direction]
    #: the onset-agnostic finding: one row (detected, drone, metric, t_u, value, score, alarms)
    finding: pd.DataFrame = field(default_factory=pd.DataFrame)
    alarms: pd.DataFrame = field(default_factory=pd.DataFrame)   # every alarm episode of the scan

    @property
    def problems(self) -> list[str]:
        return self.run.problems


def _unified_times(run: RunData) -> list[np.ndarray]:
    """The unified times of each table that has any."""
    times = (f[T].to_numpy(dtype=np.float64) for f in run.tables.values())
    return [t for t in times if len(t) and not np.isnan(t).all()]


def _last_time(run: RunData, streamed: float = np.nan) -> float:
    """The last unified time of any record (``streamed``: that of the tables left in their files)."""
    ends = [float(np.nanmax(t)) for t in _unified_times(run)]
    ends += [streamed] if np.isfinite(streamed) else []
    return max(ends) if ends else np.nan


def _first_time(run: RunData, streamed: float = np.nan) -> float:
    starts = [float(np.nanmin(t)) for t in _unified_times(run)]
    starts += [streamed] if np.isfinite(streamed) else []
    return min(starts) if starts else np.nan


def _manifest_scalars(manifest: dict) -> dict[str, float]:
    out = {}
    for key in ("sim_time_s", "wall_time_s", "real_time_factor", "n_drones"):
        value = manifest.get(key)
        out[key] = float(value) if isinstance(value, int | float) else np.nan
    return out


def _drone_table(run: RunData, window: metrics.ExecWindow | None, span: metrics.ExecWindow,
                 agents: pd.DataFrame, disc: pd.DataFrame) -> pd.DataFrame:
    drones = run.drones
    table = pd.DataFrame({"drone": drones})
    if window is not None:
        table = metrics.drone_workload(run.tables["state"], run.tables["events"], drones, window)
    inside = ((disc[T] >= span.start) & (disc[T] <= span.end)).to_numpy()   # metrics.within, one column
    d = disc["disc_h_m"][inside].groupby(disc["node"][inside]).agg(disc_h_m_mean="mean", disc_h_m_max="max")
    table = table.merge(d, left_on="drone", right_index=True, how="left")
    net = agents.rename(columns={"agent": "drone"})
    return table.merge(net, on="drone", how="left")


def _scalars(run: RunData, window: metrics.ExecWindow | None, span: metrics.ExecWindow,
             per_drone: pd.DataFrame, exec_flow: pd.DataFrame, swarm: pd.DataFrame,
             connectivity: pd.DataFrame, opts: AnalysisOptions) -> dict[str, float]:
    out = _manifest_scalars(run.manifest)
    if window is not None:
        out |= metrics.workload_summary(per_drone, window)
    out |= network.overall_stats(exec_flow)
    tx = per_drone["tx_bytes_per_s"] if "tx_bytes_per_s" in per_drone else pd.Series(dtype="float64")
    out["tx_bytes_per_s_mean"] = float(tx.mean()) if len(tx) else np.nan
    out["discrepancy_h_m_mean"] = float(per_drone["disc_h_m_mean"].mean())
    out["discrepancy_h_m_max"] = float(per_drone["disc_h_m_max"].max())
    out |= metrics.swarm_summary(metrics.within(swarm, span), run.tables["events"], sampling.tick_s(run),
                                 opts.separation_m, sampling.state_every_ticks(run))
    conn = metrics.within(connectivity, span)["connectivity"]
    out["connectivity_mean"] = float(conn.mean()) if len(conn) else np.nan
    out["connectivity_min"] = float(conn.min()) if len(conn) else np.nan
    return out


def analyze_run(source: str | Path | RunData, opts: AnalysisOptions | None = None) -> RunAnalysis:
    """Analyze one run directory (or already loaded data, which gets unified in place)."""
    opts = opts or AnalysisOptions()
    run = source if isinstance(source, RunData) else load_run(source)
    clocks = unify(run, opts.clock, sent_times=not opts.scalars_only)
    # messages left in their files (load_run's ``streamed``): matched window by window, never held
    flow, first, last = flowstream.run_flow(run, clocks, sampling.tick_s(run), sampling.max_latency_s(run),
                                            not opts.scalars_only)
    window = metrics.exec_window(run.tables["stages"], _last_time(run, last))
    if window is None:
        run.problems.append("the ground never entered EXECUTION: workload metrics are NaN")
    span = window or metrics.ExecWindow(_first_time(run, first), _last_time(run, last), False)
    if flow is None:
        flow = network.message_flow(run.tables["messages"], sampling.tick_s(run), sampling.max_latency_s(run))
    exec_flow = network.between(flow, span.start, span.end)
    full = not opts.scalars_only
    links = network.link_stats(exec_flow, span.duration) if full else pd.DataFrame()
    agents = (network.agent_stats if full else network.agent_traffic)(exec_flow, span.duration)
    disc = metrics.discrepancy(run.tables["state"], sampling.state_every_ticks(run), sampling.tick_s(run))
    per_drone = _drone_table(run, window, span, agents, disc)
    onset = _onset(run, opts)
    flagged = full or onset is not None   # the flags feed the scalars through the diagnosis only
    timeline = (drone_timeline(flow, disc, run.drones, opts.window_s, sampling.tick_s(run)) if flagged
                else pd.DataFrame())
    del disc   # a third of the state's size, not needed by what follows (the diagnosis makes its own)
    swarm = metrics.swarm_timeline(run.tables["state"], run.drones)
    connectivity = network.connectivity_timeline(flow, run.nodes, opts.graph_window_s)
    flags = anomaly.detect(timeline, opts.tests()) if flagged else pd.DataFrame()
    diagnosis = anomaly.diagnose(flags, onset) if onset else pd.DataFrame()
    scalars = _scalars(run, window, span, per_drone, exec_flow, swarm, connectivity, opts)
    scalars |= anomaly.diagnosis_scalars(diagnosis)
    specs = mission.parse_specs(run.config, run.problems)
    mission_values, directions = mission.mission_metrics(run.tables["events"], specs, span.start)
    scalars |= mission_values
    markers = mission.marker_table(run.tables["events"], specs, span.start) if full else pd.DataFrame()
    finding, alarms = _finding(run, window, opts, flow) if full else (pd.DataFrame(), pd.DataFrame())
    return RunAnalysis(run, clocks, window, flow, links, agents, per_drone, timeline, swarm, connectivity,
                       flags, diagnosis, markers, onset, scalars, directions, finding, alarms)


def _finding(run: RunData, window: metrics.ExecWindow | None, opts: AnalysisOptions,
             flow: pd.DataFrame | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The onset-agnostic diagnosis over the EXECUTION stage: its first alarm and every alarm episode,
    with the run analysis' minimum deviations. No fault event is read."""
    if window is None:
        return pd.DataFrame([{"detected": False, "alarms": 0}]), pd.DataFrame(columns=dg.ALARM_COLUMNS)
    scan = dg.DiagnosisOptions(min_deviation={k: v for k, v in opts.min_deviation.items() if k in dg.METRICS})
    series = dg.drone_series(run, scan, (window.start, window.end), flow)
    run.problems.extend(series.problems)
    alarms = dg.scan(series, scan)
    first = {"detected": False, "drone": None, "metric": None, T: np.nan, "value": np.nan, "score": np.nan}
    first |= dg.finding(alarms)
    return pd.DataFrame([first | {"alarms": len(alarms), "grid_s": series.step_s}]), alarms


def _onset(run: RunData, opts: AnalysisOptions) -> anomaly.FaultOnset | None:
    found = anomaly.fault_onset(run.tables["events"])
    if opts.fault_onset_u is None:
        if found is not None and opts.fault_target is not None:
            return anomaly.FaultOnset(found.t_u, found.name, opts.fault_target, found.extra)
        return found
    target = opts.fault_target if opts.fault_target is not None else (found.target if found else None)
    return anomaly.FaultOnset(opts.fault_onset_u, found.name if found else "given", target)
