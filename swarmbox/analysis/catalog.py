"""The built-in scalar metrics: name, unit, which direction is better, one line of meaning.

One table, read by the sweep tables (rank, paired comparison), the heatmap (darker = better) and
``compare`` (what counts as a regression). Mission-specific metrics declared in ``algo.metrics`` add
their own entries at analysis time (see :mod:`swarmbox.analysis.mission`); their units come from the
declaration (:func:`declared_units`), never from the metric's name. A count is unitless ("").
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple

Direction = Literal["lower", "higher"] | None


class MetricInfo(NamedTuple):
    unit: str
    direction: Direction
    doc: str


BUILTIN: dict[str, MetricInfo] = {
    # run
    "sim_time_s": MetricInfo("s", None, "simulated (or flown) time of the whole run"),
    "wall_time_s": MetricInfo("s", None, "wall-clock time of the run (a machine figure)"),
    "real_time_factor": MetricInfo("", None, "simulated time / wall time (a machine figure)"),
    # mission (paper Table 6)
    "mission_duration_s": MetricInfo("s", "lower", "ground EXECUTION start -> ground's next stage"),
    "distance_h_m_mean": MetricInfo("m", "lower", "mean over drones of horizontal path length"),
    "distance_h_m_std": MetricInfo("m", "lower", "population std over drones of horizontal path length"),
    "distance_h_m_total": MetricInfo("m", "lower", "sum over drones of horizontal path length"),
    "distance_3d_m_mean": MetricInfo("m", "lower", "mean over drones of 3-D path length"),
    "distance_3d_m_std": MetricInfo("m", "lower", "population std over drones of 3-D path length"),
    "busy_s_mean": MetricInfo("s", None, "mean over drones of EXECUTION start -> own completion"),
    "busy_s_std": MetricInfo("s", "lower", "population std over drones of busy time (workload deviation)"),
    "utilization_mean": MetricInfo("", "higher", "mean over drones of busy / mission duration (0..1)"),
    "utilization_std": MetricInfo("", "lower", "population std over drones of utilization"),
    "idle_s_mean": MetricInfo("s", "lower", "mean over drones of mission duration - busy"),
    "completed_fraction": MetricInfo("", "higher", "fraction of drones that reported completion"),
    # network (EXECUTION, unified clock)
    "latency_ms_mean": MetricInfo("ms", "lower", "mean one-way latency of delivered messages"),
    "latency_ms_p50": MetricInfo("ms", "lower", "median one-way latency"),
    "latency_ms_p95": MetricInfo("ms", "lower", "95th percentile one-way latency"),
    "latency_ms_max": MetricInfo("ms", "lower", "largest one-way latency"),
    "loss_ratio": MetricInfo("", "lower", "lost / sent over all links"),
    "tx_bytes_per_s_mean": MetricInfo("B/s", "lower", "mean over agents of bytes sent per second"),
    # estimation
    "discrepancy_h_m_mean": MetricInfo("m", "lower", "mean over drones of mean |GNSS - estimate| (N, E)"),
    "discrepancy_h_m_max": MetricInfo("m", "lower", "largest horizontal GNSS - estimate distance"),
    # safety
    "min_separation_m": MetricInfo("m", "higher", "smallest 3-D distance between two drones"),
    "time_below_separation_s": MetricInfo("s", "lower", "time with some pair closer than the threshold"),
    "collision_events": MetricInfo("", "lower", "collision events logged over the whole run"),
    "safety_events": MetricInfo("", "lower", "safety-monitor interventions over the whole run"),
    # swarm
    "order_mean": MetricInfo("", None, "mean velocity alignment |sum v| / sum |v|"),
    "connectivity_mean": MetricInfo("", "higher", "mean algebraic connectivity of the comm graph"),
    "connectivity_min": MetricInfo("", "higher", "smallest algebraic connectivity of the comm graph"),
    # diagnosis (first anomaly after the fault onset, any monitored metric)
    "anomaly_t_f_s": MetricInfo("s", "lower", "time from fault onset to first anomaly (t_f)"),
    "anomaly_tau_d": MetricInfo("", None, "metric value at t_f (tau_d)"),
    "anomaly_sigma_a": MetricInfo("IQR", "higher", "distance beyond the fence at t_f (Sigma_a)"),
    "anomaly_is_target": MetricInfo("", "higher", "1 if the first flagged drone is the fault target"),
}

#: Figures of the computer that ran the simulation, not of the algorithm: sweep tables report them
#: but never rank, compare or colour them as results.
MACHINE_METRICS = frozenset({"wall_time_s", "real_time_factor"})

#: Unit of each injected fault's magnitude (the detection benchmark's x axis).
FAULT_UNITS: dict[str, str] = {"gps_drift": "m/s", "gps_bias": "m", "gps_noise": "x sigma", "latency": "ms",
                               "packet_loss": "loss probability", "burst_loss": "p_enter"}

#: A sweep summary's run counts (rows of every group) and which direction is better.
RUN_COUNTS: dict[str, Direction] = {
    "runs_attempted": "higher", "runs_ok": "higher", "runs_aborted": "lower", "runs_failed": "lower",
    "runs_interrupted": "lower", "success_rate": "higher",
}

#: Metrics over the mission window (ground EXECUTION -> its next stage). An abort ends that window early,
#: so an aborted run would look like a fast, well-used mission: they are taken from ``ok`` runs only.
COMPLETION_METRICS = frozenset({"mission_duration_s", "busy_s_mean", "busy_s_std", "utilization_mean",
                                "utilization_std", "idle_s_mean"})

#: Per monitored metric the diagnosis adds ``<m>_t_f_s``, ``<m>_tau_d``, ``<m>_sigma_a``, ``<m>_is_target``.
_DIAG_SUFFIX: dict[str, Direction] = {
    "_t_f_s": "lower", "_tau_d": None, "_sigma_a": "higher", "_is_target": "higher",
}


def direction_of(name: str, extra: dict[str, Direction] | None = None) -> Direction:
    """Better direction of a metric: declared (``extra``) > built-in > diagnosis suffix > None."""
    if extra and name in extra:
        return extra[name]
    if name in BUILTIN:
        return BUILTIN[name].direction
    if name in RUN_COUNTS:
        return RUN_COUNTS[name]
    for suffix, direction in _DIAG_SUFFIX.items():
        if name.endswith(suffix):
            return direction
    return None


#: Unit of the diagnosis metrics' tau_d (a value of the monitored metric), per monitored metric.
_MONITORED_UNITS = {"latency_ms": "ms", "loss_ratio": "", "disc_n_m": "m", "disc_e_m": "m", "disc_d_m": "m"}
_DIAG_UNITS = {"_t_f_s": "s", "_sigma_a": "IQR", "_is_target": ""}


def unit_of(name: str, declared: dict[str, str] | None = None) -> str:
    """Unit of a metric: declared (``declared_units``) > built-in > diagnosis suffix; "" when unitless or
    unknown. Never guessed from tokens of the name (``delivery_wait_s_count`` is a count, not seconds)."""
    if declared and name in declared:
        return declared[name]
    if name in BUILTIN:
        return BUILTIN[name].unit
    if name in RUN_COUNTS:
        return ""
    for suffix, unit in _DIAG_UNITS.items():
        if name.endswith(suffix):
            return unit
    if name.endswith("_tau_d"):
        return _MONITORED_UNITS.get(name[: -len("_tau_d")], "")
    return ""


def declared_units(config: dict[str, Any]) -> dict[str, str]:
    """Units of the mission metrics an algorithm declares in ``algo.metrics``.

    ``count`` is unitless; ``measure: since_exec_start`` is in s; a ``field`` metric has the entry's
    ``unit`` key ("" when absent); with neither every marker counts 1 (unitless).
    """
    entries = ((config.get("algo") or {}).get("metrics")) or []
    units: dict[str, str] = {}
    for entry in entries if isinstance(entries, list) else []:
        if not isinstance(entry, dict) or not entry.get("name"):
            continue
        aggs = entry.get("agg", ["mean"])
        aggs = [aggs] if isinstance(aggs, str) else list(aggs)
        unit = "s" if entry.get("measure") == "since_exec_start" else str(entry.get("unit", "")) \
            if entry.get("field") else ""
        for agg in aggs:
            units[f"{entry['name']}_{agg}"] = "" if agg == "count" else unit
    return units
