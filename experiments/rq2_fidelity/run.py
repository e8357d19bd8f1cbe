"""RQ2: fly the paper's formation on ``sim``, on ``mavsim`` (the px4 bridge over UDP) and, when a
PX4 build is given, on PX4 SITL; write the per-drone RMSE table, the overlaid trajectories (paper
Fig. 3) and the runtime's overhead on the px4 path.

    python experiments/rq2_fidelity/run.py                   # full mission (about 2 minutes)
    python experiments/rq2_fidelity/run.py --ci              # shortened mission (about 40 s)
    python experiments/rq2_fidelity/run.py --px4-build ~/PX4-Autopilot   # also PX4 SITL (SIH)

Each run is a separate process (``--one``), so the runner's memory is measured without this
script's pandas and matplotlib.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
MISSION = ["algo=formation", "mission=formation"]
CI_MISSION = ["algo.params.start_s=2", "algo.params.angular_rate_rad_s=0.6", "algo.params.complete_after_s=8"]
DRONES = [0, 1, 2, 3]


def backends(speed: float, px4_build: str | None) -> dict[str, list[str]]:
    out = {"sim": ["backend=sim"], "mavsim": ["backend=mavsim", f"run.speed={speed:g}"]}
    if px4_build:
        out["px4_sitl"] = ["backend=px4", f"backend.px4_build={px4_build}", f"run.speed={min(speed, 2.0):g}"]
    return out


# ---- one run, in its own process (no pandas here) ---------------------------------------------------
def run_one(run_dir: Path, overrides: list[str]) -> int:
    """Execute one run into ``run_dir`` and leave ``overhead.json`` beside its logs."""
    sys.path.insert(0, str(ROOT))
    from hydra import compose, initialize_config_dir
    from omegaconf import open_dict

    from swarmbox.run.config import GROUPS, register
    from swarmbox.run.runner import execute

    register()
    overrides = [*overrides, f"run.out_dir={run_dir}", "run.progress=false"]
    with initialize_config_dir(config_dir=str(ROOT / "swarmbox" / "conf"), version_base="1.3"):
        cfg = compose("config", overrides=overrides, return_hydra_config=True)
    choices = {g: str(cfg.hydra.runtime.choices.get(g)) for g in GROUPS}
    with open_dict(cfg):
        del cfg["hydra"]
    captured: dict[str, Any] = {}
    cpu0 = _cpu_s()
    manifest = execute(cfg, run_dir, choices, overrides, lambda swarm: captured.update(backend=swarm.backend))
    backend = captured.get("backend")
    overhead = {
        "status": manifest["status"], "sim_time_s": manifest["sim_time_s"],
        "wall_time_s": manifest["wall_time_s"], "runner_cpu_s": _cpu_s() - cpu0,
        "runner_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "heavy_modules": sorted({"pandas", "matplotlib", "seaborn"} & set(sys.modules)),
        "vehicle_processes": getattr(backend, "process_stats", []),
        "mavlink": backend.link_stats() if hasattr(backend, "link_stats") else [],
    }
    (run_dir / "overhead.json").write_text(json.dumps(overhead, indent=2))
    return 0 if manifest["status"] == "ok" else 1


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


# ---- the experiment --------------------------------------------------------------------------------
def swarm_traffic_kb_s(run_dir: Path, sim_time_s: float) -> float:
    """Mean bytes the drone nodes send per second of mission time, per agent (KB/s)."""
    import pandas as pd

    total = 0
    for i in DRONES:
        path = run_dir / "logs" / f"drone_{i}" / "messages.parquet"
        msgs = pd.read_parquet(path, columns=["kind", "nbytes"])
        total += int(msgs.loc[msgs["kind"] == "send", "nbytes"].sum())
    return total / len(DRONES) / sim_time_s / 1e3


def overhead_row(label: str, run_dir: Path) -> dict[str, Any]:
    o = json.loads((run_dir / "overhead.json").read_text())
    sim_s, n = o["sim_time_s"], len(DRONES)
    procs = o["vehicle_processes"]
    mav_bytes = sum(m["rx_bytes"] + m["tx_bytes"] for m in o["mavlink"])
    return {
        "backend": label, "sim_time_s": round(sim_s, 1), "wall_time_s": round(o["wall_time_s"], 1),
        "runner_rss_mb": round(o["runner_maxrss_mb"], 1),
        "runner_cpu_pct_per_agent_at_1x": round(100 * o["runner_cpu_s"] / sim_s / n, 2),
        "swarm_traffic_kb_s_per_agent": round(swarm_traffic_kb_s(run_dir, sim_s), 2),
        "mavlink_kb_s_per_vehicle": round(mav_bytes / n / sim_s / 1e3, 2) if o["mavlink"] else None,
        "vehicle_rss_mb": round(max(p.get("vmhwm_mb", 0) for p in procs), 1) if procs else None,
        "heavy_modules_in_runner": ",".join(o["heavy_modules"]) or "-",
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ci", action="store_true", help="shortened mission (one fast lap)")
    ap.add_argument("--speed", type=float, default=4.0, help="run.speed of the mavsim run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--px4-build", default=os.environ.get("SWARMBOX_PX4_BUILD"))
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "rq2_fidelity")
    ap.add_argument("--one", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        return run_one(Path(args.one[0]), args.one[1:])
    out = args.out / time.strftime("%Y-%m-%d_%H-%M-%S")
    common = [*MISSION, *(CI_MISSION if args.ci else []), f"seed={args.seed}"]
    runs: dict[str, Path] = {}
    for label, extra in backends(args.speed, args.px4_build).items():
        run_dir = out / label
        print(f"[rq2] {label}: {' '.join(extra)}", flush=True)
        code = subprocess.call([sys.executable, __file__, "--one", str(run_dir), *common, *extra], cwd=ROOT)
        if code != 0:
            print(f"[rq2] {label} run failed (see {run_dir}/run.json)", file=sys.stderr)
            return 1
        runs[label] = run_dir
    return report(runs, out)


def markdown(frame) -> str:
    """A GitHub-flavoured Markdown table (no optional dependency)."""
    head = "| " + " | ".join(map(str, frame.columns)) + " |"
    rule = "|" + "|".join("---" for _ in frame.columns) + "|"
    rows = ["| " + " | ".join(map(str, row)) + " |" for row in frame.itertuples(index=False)]
    return "\n".join([head, rule, *rows])


def report(runs: dict[str, Path], out: Path) -> int:
    import pandas as pd

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from fidelity import compare, trajectories

    ref = runs["sim"]
    table = pd.concat([compare(ref, d, DRONES, f"sim vs {label}")
                       for label, d in runs.items() if label != "sim"])
    overhead = pd.DataFrame([overhead_row(label, d) for label, d in runs.items()])
    table.to_csv(out / "fidelity.csv", index=False)
    overhead.to_csv(out / "overhead.csv", index=False)
    text = ("## Per-drone RMSE (m, horizontal)\n\n" + markdown(table.round(3))
            + "\n\n## Overhead\n\n" + markdown(overhead) + "\n")
    (out / "fidelity.md").write_text(text)
    trajectories(runs, DRONES).savefig(out / "fig3_trajectories.png", dpi=130, bbox_inches="tight")
    print(text + f"\n[rq2] written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
