"""Per-agent CPU, memory and bandwidth of the distributed runtime (``run.runtime=processes``).

    python experiments/net_overhead/measure.py                 # 4 and 9 agents, formation, mavsim
    python experiments/net_overhead/measure.py --sizes 4 9 36

Each size is one real run (ground + N agent processes + one mavsim host flying the N vehicles,
``--vehicle-host agent``: N mavsim processes instead; Zenoh on 127.0.0.1, 1x real time); a size
of 36 flies ``mission=formation36``. Runs are kept under ``--out`` (one directory per size; an
existing run is never overwritten), so the script can be repeated with a new ``--out``.
Figures come from each node's ``nodes/<node>.json``: CPU time over the node's wall
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
MISSIONS = {4: ["algo=formation", "mission=formation"], 9: ["algo=formation9", "mission=formation9"],
            36: ["algo=formation9", "mission=formation36"]}


def overrides_for(n: int) -> list[str]:
    if n in MISSIONS:
        return MISSIONS[n]
    side = int(round(n ** 0.5))
    if side * side != n:
        raise SystemExit(f"--sizes: {n} is neither 4, 9 nor a square (a hover grid is used)")
    grid = ",".join(f"{i}:[{5.0 * (i // side)},{5.0 * (i % side)}]" for i in range(n))
    return ["algo=hover", "mission=hover", f"mission.swarm_size={n}", "mission.initial_positions=null",
            f"mission.initial_positions={{{grid}}}"]


def measure(n: int, out: Path, host: str) -> dict:
    run_dir = out / f"agents_{n}"
    if (run_dir / "run.json").exists():
        raise SystemExit(f"{run_dir} already holds a run: pass another --out")
    cmd = [sys.executable, "-m", "swarmbox.run", "run.runtime=processes", "backend=mavsim",
           f"run.net.vehicle_host={host}", f"run.net.ready_timeout_s={max(120, 10 * n)}",
           f"run.out_dir={run_dir}", "run.progress=false", *overrides_for(n)]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    load_before = os.getloadavg()[0]
    subprocess.run(cmd, env=env, check=False, timeout=3600)
    manifest = json.loads((run_dir / "run.json").read_text())
    agents = [r for name, r in manifest["node_results"].items() if name != "ground" and "wall_s" in r]
    if not agents:
        raise SystemExit(f"{n} agents: no agent finished ({manifest['status']}: {manifest['reason']})")
    ground = manifest["node_results"]["ground"]

    def med(f) -> float:
        return statistics.median(f(r) for r in agents)

    vh = manifest.get("vehicle_host") or {}
    return {"agents": n, "status": manifest["status"], "load": f"{load_before:.1f}-{os.getloadavg()[0]:.1f}",
            "sim_s": manifest["sim_time_s"], "host": host,
            "host_cpu_pct": 100 * vh["cpu_s"] / vh["wall_s"] if vh else float("nan"),
            "host_rss_mb": vh.get("vmhwm_mb", float("nan")),
            "cpu_pct": med(lambda r: 100 * r["cpu_s"] / r["wall_s"]),
            "rss_mb": med(lambda r: r["vmhwm_mb"]), "rss_max_mb": max(r["vmhwm_mb"] for r in agents),
            "out_kb_s": med(lambda r: r["bytes_out"] / r["wall_s"] / 1e3),
            "in_kb_s": med(lambda r: r["bytes_in"] / r["wall_s"] / 1e3),
            "ground_cpu_pct": 100 * ground["cpu_s"] / ground["wall_s"], "ground_rss_mb": ground["vmhwm_mb"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[4, 9])
    ap.add_argument("--out", type=Path, default=None, help="keep the runs here (default: a temp dir)")
    ap.add_argument("--vehicle-host", choices=("shared", "agent"), default="shared",
                    help="one mavsim host for all vehicles (default) or one vehicle process per agent")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="swarmbox_overhead_"))
    rows = []
    for n in args.sizes:   # one row at a time, so a long series shows progress
        rows.append(measure(n, out, args.vehicle_host))
        print(f"# {n} agents: {rows[-1]['status']}", flush=True)
    cols = ["agents", "status", "load", "sim_s", "cpu_pct", "rss_mb", "rss_max_mb", "out_kb_s", "in_kb_s",
            "ground_cpu_pct", "ground_rss_mb", "host", "host_cpu_pct", "host_rss_mb"]
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for r in rows:
        print("| " + " | ".join(f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")

if __name__ == "__main__":
    main()
