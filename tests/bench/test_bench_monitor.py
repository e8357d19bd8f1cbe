"""The live dashboard's cost to the tick loop: 36 drones in simulation, dashboard on vs off.

Runs are interleaved (off, on, off, on, ...) so that load on a shared machine hits both alike; the
dashboard renders every frame to a terminal-compatible stream (``TTY_COMPATIBLE=1``), as it would on
a field laptop. Figures in ``extra_info``, per mode: the tick loop's wall time (minimum: the least
disturbed run, and median) and the CPU time of the thread that runs the loop (median; insensitive to
other processes' load), their on/off ratios, and the dashboard thread's own CPU share.

    python -m pytest tests/bench/test_bench_monitor.py --benchmark-enable -s
"""

import statistics
import time

import pytest

from tests.bench.test_bench_run import grid, one_run

HOVER = ["algo=hover", "mission=hover", "algo.params.hover_s=20"]


def interleaved(tmp_path_factory, rounds: int) -> dict:
    wall = {"off": [], "on": []}
    cpu = {"off": [], "on": []}
    shares = []
    for _ in range(rounds):
        for mode in ("off", "on"):
            t0 = time.thread_time()
            m = one_run(tmp_path_factory, [*HOVER, f"run.monitor={mode}"], grid(36))
            cpu[mode].append(time.thread_time() - t0)
            wall[mode].append(m["wall_time_s"])
            if mode == "on":
                shares.append(m["monitor"]["cpu_share"])
    med = {k: statistics.median(v) for k, v in cpu.items()}
    return {
        "loop_wall_min_off_s": round(min(wall["off"]), 4), "loop_wall_min_on_s": round(min(wall["on"]), 4),
        "wall_min_on_over_off": round(min(wall["on"]) / min(wall["off"]), 4),
        "wall_median_on_over_off": round(statistics.median(wall["on"]) / statistics.median(wall["off"]), 4),
        "run_thread_cpu_median_off_s": round(med["off"], 4),
        "run_thread_cpu_median_on_s": round(med["on"], 4),
        "thread_cpu_on_over_off": round(med["on"] / med["off"], 4),
        "monitor_cpu_share": round(statistics.median(shares), 5), "rounds": rounds,
        "wall_off_s": [round(x, 3) for x in wall["off"]], "wall_on_s": [round(x, 3) for x in wall["on"]],
    }


@pytest.mark.slow
def test_dashboard_on_vs_off_36_drones(benchmark, tmp_path_factory, monkeypatch):
    monkeypatch.setenv("TTY_COMPATIBLE", "1")
    monkeypatch.setenv("COLUMNS", "110")
    monkeypatch.setenv("LINES", "50")
    rounds = 1 if benchmark.disabled else 7   # a plain test run only checks that both modes work
    result = benchmark.pedantic(interleaved, args=(tmp_path_factory, rounds), rounds=1, iterations=1)
    benchmark.extra_info.update(result)
    print(result)
