"""The live dashboard's cost to the tick loop: 36 drones in simulation, dashboard on vs off.

Runs are interleaved (off, on, off, on, ...) so that load on a shared machine hits both alike; the
dashboard renders every frame to a terminal-compatible stream (``TTY_COMPATIBLE=1``), as it would on
a field laptop. Figures in ``extra_info``: median tick-loop wall time off and on, their ratio, and
the monitor's own share of the process CPU.

    python -m pytest tests/bench/test_bench_monitor.py --benchmark-enable -s
"""

import statistics

import pytest

from tests.bench.test_bench_run import grid, one_run

HOVER = ["algo=hover", "mission=hover", "algo.params.hover_s=20"]


def interleaved(tmp_path_factory, rounds: int) -> dict:
    loop = {"off": [], "on": []}
    shares = []
    for _ in range(rounds):
        for mode in ("off", "on"):
            m = one_run(tmp_path_factory, [*HOVER, f"run.monitor={mode}"], grid(36))
            loop[mode].append(m["wall_time_s"])
            if mode == "on":
                shares.append(m["monitor"]["cpu_share"])
    off, on = statistics.median(loop["off"]), statistics.median(loop["on"])
    return {"loop_off_s": round(off, 4), "loop_on_s": round(on, 4), "on_over_off": round(on / off, 4),
            "monitor_cpu_share": round(statistics.median(shares), 5), "rounds": rounds,
            "all_off_s": [round(x, 3) for x in loop["off"]], "all_on_s": [round(x, 3) for x in loop["on"]]}


@pytest.mark.slow
def test_dashboard_on_vs_off_36_drones(benchmark, tmp_path_factory, monkeypatch):
    monkeypatch.setenv("TTY_COMPATIBLE", "1")
    monkeypatch.setenv("COLUMNS", "110")
    monkeypatch.setenv("LINES", "50")
    result = benchmark.pedantic(interleaved, args=(tmp_path_factory, 5), rounds=1, iterations=1)
    benchmark.extra_info.update(result)
    print(result)
