"""What the live dashboard costs the ground node on a real-time run (MAVLink vehicles, speed 1).

Two runtimes, each a real ``python -m swarmbox.run`` with ``backend=mavsim`` drawing to a
terminal-compatible stream (``TTY_COMPATIBLE=1``, 110 x 40), as over SSH on a field laptop:

- ``run.runtime=processes``: the ground is its own OS process, so its CPU is the ground node's. Per
  round the dashboard is off, on at 2 Hz (the default) and on at 4 Hz, interleaved. Recorded: the
  monitor's own CPU (drawing thread + snapshots on the tick thread, ``time.thread_time``) over the
  ground process's CPU during the same span, and the ground process's whole CPU on vs off.
- the single-process runtime (ground, agents and vehicle links in one process): the monitor's CPU
  over that process's CPU, and as a share of one core.

    python -m pytest tests/bench/test_bench_monitor_realtime.py --benchmark-enable -s -m slow

A plain test run (benchmarks disabled) flies one short hover with the dashboard in the ground's own
process, so CI checks that it draws and measures (the single-process dashboard has its tmux test);
the figures in docs/monitor.md come from the enabled run above (the formation mission, 85 s a run).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHORT = ["algo=hover", "mission=hover", "algo.params.hover_s=4"]


def fly(run_dir: Path, overrides: list[str]) -> dict:
    env = dict(os.environ, TTY_COMPATIBLE="1", COLUMNS="110", LINES="40")
    with open(run_dir.parent / f"{run_dir.name}.screen", "wb") as screen:
        proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "backend=mavsim", "run.speed=1",
                               f"run.out_dir={run_dir}", *overrides], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=screen, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout.decode()[-2000:]
    if "run.monitor=on" in overrides:   # the dashboard drew the swarm (from the ground's own process)
        drawn = (run_dir.parent / f"{run_dir.name}.screen").read_text(errors="replace")
        assert "drones 4/4 alive" in drawn and "stage TERMINATION" in drawn, drawn[-2000:]
    return json.loads((run_dir / "run.json").read_text())


def _share(mon: dict) -> float:
    return (mon["render_cpu_s"] + mon["snapshot_s"]) / mon["process_cpu_s"]


def measure(tmp: Path, mission: list[str], rounds: int, rates: tuple[float, ...], with_off: bool,
            runtimes: tuple[str, ...] = ("processes", "single")) -> dict:
    n = 0
    procs: dict[str, list[float]] = {}
    shares: dict[str, list[float]] = {}
    frame_ms: dict[str, list[float]] = {}
    core: dict[str, list[float]] = {}
    for _ in range(rounds):
        for runtime in runtimes:
            modes = (["off"] if runtime == "processes" and with_off else []) + [f"{hz:g}" for hz in rates]
            for mode in modes:
                n += 1
                over = ["run.monitor=off"] if mode == "off" else ["run.monitor=on", f"run.monitor_hz={mode}"]
                if runtime == "processes":
                    over.append("run.runtime=processes")
                m = fly(tmp / f"run{n}", [*mission, *over])
                assert m["status"] == "ok", m["reason"]
                key = f"{runtime}@{mode}"
                if runtime == "processes":
                    g = m["node_results"]["ground"]
                    procs.setdefault(key, []).append(g["cpu_s"] / g["wall_s"])
                    mon = g.get("monitor")
                else:
                    mon = m.get("monitor")
                if mon:
                    assert not mon["error"] and mon["frames"] > 0, mon
                    shares.setdefault(key, []).append(_share(mon))
                    frame_ms.setdefault(key, []).append(1e3 * mon["render_cpu_s"] / max(mon["wakeups"], 1))
                    core.setdefault(key, []).append((mon["render_cpu_s"] + mon["snapshot_s"]) / mon["wall_s"])
    med = statistics.median
    out = {"rounds": rounds, "load_avg": os.getloadavg()[0],
           "monitor_over_process_cpu": {k: round(med(v), 4) for k, v in shares.items()},
           "monitor_share_of_a_core": {k: round(med(v), 5) for k, v in core.items()},
           "render_ms_per_wakeup": {k: round(med(v), 3) for k, v in frame_ms.items()},
           "ground_process_core_share": {k: round(med(v), 4) for k, v in procs.items()},
           "all_shares": {k: [round(x, 4) for x in v] for k, v in shares.items()}}
    if "processes@off" in procs:
        out["ground_cpu_on_over_off"] = {k: round(med(v) / med(procs["processes@off"]), 3)
                                         for k, v in procs.items() if k != "processes@off"}
    return out


@pytest.mark.slow
def test_dashboard_cost_on_real_time_runs(benchmark, tmp_path):
    if benchmark.disabled:   # CI: one short run of the ground in its own process (about 20 s)
        args = (tmp_path, SHORT, 1, (2.0,), False, ("processes",))
    else:
        args = (tmp_path, [], 2, (2.0, 4.0), True)
    result = benchmark.pedantic(measure, args=args, rounds=1, iterations=1)
    benchmark.extra_info.update(result)
    assert "processes@2" in result["monitor_over_process_cpu"]
    print(json.dumps(result, indent=1))
