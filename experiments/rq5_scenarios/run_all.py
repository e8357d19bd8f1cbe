"""Run the RQ5 scenario library (paper Table 7 / Fig. 5) one mission at a time, and time each run.

    python experiments/rq5_scenarios/run_all.py                      # the eight missions, 36 drones
    python experiments/rq5_scenarios/run_all.py --scale              # + chevron and network at 200
    python experiments/rq5_scenarios/run_all.py --only chevron network --seed 3

Each run goes to ``<out>/<name>/`` (a finished one is kept and not re-run) and one row per run is
written to ``<out>/timing.csv``: simulated time, the tick loop's wall time and real-time factor
(from ``run.json``), and the CPU time of the whole process (start-up and log writing included),
which is the fairer number on a shared machine.
"""

from __future__ import annotations

import argparse
import csv
import json
import resource
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: name -> (Table 7 case, command-line overrides). The 36-drone missions first, then the 200s.
SCENARIOS: dict[str, tuple[str, list[str]]] = {
    "airview": ("1 airview (hybrid)", ["algo=airview", "mission=airview"]),
    "delivery": ("2 delivery (hybrid)", ["algo=delivery_distance_dynamic", "mission=delivery36"]),
    "chevron": ("3 formation (leader-follower)", ["algo=chevron", "mission=chevron"]),
    "network": ("4 network (decentralized)", ["algo=network", "mission=network"]),
    "tracking": ("5 tracking (centralized)", ["algo=tracking", "mission=tracking"]),
    "adaptive": ("6 adaptive swarm (ported)", ["algo=adaptive", "mission=adaptive"]),
    "flocking": ("7 optimized flocking (ported)", ["algo=flocking", "mission=flocking"]),
    "socratic": ("8 socratic swarm (ported)", ["algo=socratic", "mission=socratic"]),
}
SCALE: dict[str, tuple[str, list[str]]] = {
    "chevron200": ("3 formation, 200 drones", ["algo=chevron", "mission=chevron200"]),
    "network200": ("4 network, 200 drones", ["algo=network", "mission=network200"]),
}
FIELDS = ["name", "case", "n_drones", "status", "sim_time_s", "loop_wall_s", "rtf_loop", "cpu_s",
          "rtf_cpu", "reason"]


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_one(name: str, case: str, overrides: list[str], out: Path, seed: int) -> dict:
    """Run one scenario in a fresh interpreter (as a user would) and return its timing row."""
    run_dir = out / name
    cpu_s = float("nan")
    if not (run_dir / "run.json").exists():
        before = children_cpu_s()
        cmd = [sys.executable, "-m", "swarmbox.run", *overrides, f"seed={seed}", f"run.out_dir={run_dir}",
               "run.progress=false"]
        print(" ".join(cmd[1:]), flush=True)
        subprocess.run(cmd, cwd=ROOT, check=False)
        cpu_s = children_cpu_s() - before
    manifest = json.loads((run_dir / "run.json").read_text())
    sim = float(manifest["sim_time_s"])
    return {"name": name, "case": case, "n_drones": manifest["n_drones"], "status": manifest["status"],
            "sim_time_s": round(sim, 1), "loop_wall_s": round(float(manifest["wall_time_s"]), 1),
            "rtf_loop": round(float(manifest["real_time_factor"] or 0.0), 2), "cpu_s": round(cpu_s, 1),
            "rtf_cpu": round(sim / cpu_s, 2) if cpu_s == cpu_s and cpu_s > 0 else "",
            "reason": manifest["reason"]}


def merge_rows(path: Path, rows: list[dict]) -> None:
    """Update ``timing.csv``: rows of this invocation replace earlier rows of the same name."""
    old = {}
    if path.exists():
        with path.open() as f:
            old = {r["name"]: r for r in csv.DictReader(f)}
    for row in rows:
        if row["cpu_s"] == row["cpu_s"] or row["name"] not in old:   # keep the measured CPU time
            old[row["name"]] = row
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(old.values())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "rq5_scenarios")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scale", action="store_true", help="also chevron and network with 200 drones")
    parser.add_argument("--only", nargs="*", help="scenario names to run (default: all)")
    args = parser.parse_args(argv)
    todo = {**SCENARIOS, **(SCALE if args.scale or args.only else {})}
    if args.only:
        unknown = sorted(set(args.only) - set(todo))
        if unknown:
            parser.error(f"unknown scenarios {unknown}; known: {sorted(todo)}")
        todo = {k: v for k, v in todo.items() if k in args.only}
    args.out.mkdir(parents=True, exist_ok=True)
    rows = [run_one(name, case, overrides, args.out, args.seed) for name, (case, overrides) in todo.items()]
    merge_rows(args.out / "timing.csv", rows)
    for r in rows:
        print(f"{r['name']:<11} N={r['n_drones']:<4} {r['status']:<8} sim {r['sim_time_s']:>6} s  "
              f"loop RTF {r['rtf_loop']:>6}  CPU RTF {r['rtf_cpu']}", flush=True)
    return 0 if all(r["status"] == "ok" for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
