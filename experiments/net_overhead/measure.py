"""Per-agent CPU, memory and bandwidth of the distributed runtime (``run.runtime=processes``).

    python experiments/net_overhead/measure.py                 # 4 and 9 agents, formation, mavsim
    python experiments/net_overhead/measure.py --sizes 4 9 36

Each size is one real run (ground + N agent processes + N mavsim autopilots, Zenoh on 127.0.0.1,
1x real time). Figures come from each node's ``nodes/<node>.json``: CPU time over the node's wall
time, peak resident memory (VmHWM) and the signed frames it sent and received per second. The
load average is printed with the table, since the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = {4: ["algo=formation", "mission=formation"], 9: ["algo=formation9", "mission=formation9"]}


def overrides_for(n: int) -> list[str]:
    if n in MISSIONS:
        return MISSIONS[n]
    side = int(round(n ** 0.5))
    if side * side != n:
        raise SystemExit(f"--sizes: {n} is neither 4, 9 nor a square (a hover grid is used)")
    grid = ",".join(f"{i}:[{5.0 * (i // side)},{5.0 * (i % side)}]" for i in range(n))
    return ["algo=hover", "mission=hover", f"mission.swarm_size={n}", "mission.initial_positions=null",
            f"mission.initial_positions={{{grid}}}"]


def measure(n: int, out: Path) -> dict:
    run_dir = out / f"agents_{n}"
    cmd = [sys.executable, "-m", "swarmbox.run", "run.runtime=processes", "backend=mavsim",
           f"run.out_dir={run_dir}", "run.progress=false", *overrides_for(n)]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    subprocess.run(cmd, env=env, check=False, timeout=3600)
    manifest = json.loads((run_dir / "run.json").read_text())
    agents = [r for name, r in manifest["node_results"].items() if name != "ground"]
    ground = manifest["node_results"]["ground"]

    def med(f) -> float:
        return statistics.median(f(r) for r in agents)

    return {"agents": n, "status": manifest["status"], "load": os.getloadavg()[0],
            "cpu_pct": med(lambda r: 100 * r["cpu_s"] / r["wall_s"]),
            "rss_mb": med(lambda r: r["vmhwm_mb"]), "rss_max_mb": max(r["vmhwm_mb"] for r in agents),
            "out_kb_s": med(lambda r: r["bytes_out"] / r["wall_s"] / 1e3),
            "in_kb_s": med(lambda r: r["bytes_in"] / r["wall_s"] / 1e3),
            "ground_cpu_pct": 100 * ground["cpu_s"] / ground["wall_s"], "ground_rss_mb": ground["vmhwm_mb"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[4, 9])
    ap.add_argument("--out", type=Path, default=None, help="keep the runs here (default: a temp dir)")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="swarmbox_overhead_"))
    rows = [measure(n, out) for n in args.sizes]
    cols = ["agents", "status", "load", "cpu_pct", "rss_mb", "rss_max_mb", "out_kb_s", "in_kb_s",
            "ground_cpu_pct", "ground_rss_mb"]
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for r in rows:
        print("| " + " | ".join(f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")

if __name__ == "__main__":
    main()
