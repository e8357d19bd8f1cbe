"""RQ2: fly the paper's formation on ``sim``, on ``mavsim`` (the px4 bridge over UDP) and, when a
PX4 build is given, on PX4 SITL; write the per-drone RMSE table, the overlaid trajectories (paper
Fig. 3) and the runtime's overhead on the px4 path; and the sim-vs-PX4 fidelity table (lag behind
the setpoint, RMSE vs setpoint, sim-vs-PX4 and PX4-vs-PX4 RMSE) against PX4 flights — fresh ones
with ``--px4-build``, else the committed reference ``data/px4_formation.parquet``.

    python experiments/rq2_fidelity/run.py                   # full mission (about 2 minutes)
    python experiments/rq2_fidelity/run.py --ci              # shortened mission (about 40 s)
    python experiments/rq2_fidelity/run.py --px4-build ~/PX4-Autopilot   # also PX4 SITL (SIH)
    python experiments/rq2_fidelity/run.py --px4-only --px4-build ../shared/px4-sitl --px4-runs 4 \
        --px4-boot-wait 10 45 80 115 \
        --save-reference experiments/rq2_fidelity/data/px4_formation.parquet   # re-record PX4 at 1x

PX4 SIH draws the same sensor-noise sequence from every boot, so two PX4 runs with the same timing
fly the same noise; ``--px4-boot-wait`` boots each run's instances that many wall seconds before
its mission starts (one value per run), which makes the runs' noise independent.

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


REFERENCE = Path(__file__).resolve().parent / "data" / "px4_formation.parquet"


def backends(speed: float, px4_build: str | None, px4_runs: int = 1, px4_speed: float = 1.0,
             mavsim: bool = True) -> dict[str, list[str]]:
    """label -> overrides of every run; PX4 runs are ``px4_sitl`` or ``px4_1``, ``px4_2``, ..."""
    out = {"sim": ["backend=sim"], "sim_px4": ["backend=sim_px4"]}
    if mavsim:
        out["mavsim"] = ["backend=mavsim", f"run.speed={speed:g}"]
    if px4_build:
        px4 = ["backend=px4", f"backend.px4_build={px4_build}", "backend.ground_truth=true",
               f"run.speed={px4_speed:g}"]
        labels = ["px4_sitl"] if px4_runs == 1 else [f"px4_{k + 1}" for k in range(px4_runs)]
        out.update({label: px4 for label in labels})
    return out


# ---- one run, in its own process (no pandas here) ---------------------------------------------------
def run_one(run_dir: Path, overrides: list[str], boot_wait_s: float = 0.0) -> int:
    """Execute one run into ``run_dir`` and leave ``overhead.json`` beside its logs; a PX4 run with
    ``boot_wait_s`` > 0 flies on instances booted that many wall seconds earlier."""
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
    launcher = None
    if boot_wait_s > 0:
        launcher = boot_px4(cfg, boot_wait_s)
        connect = {"px4_build": None, "wait_ready": True, "connections": launcher.connections(),
                   "system_ids": launcher.system_ids()}
        with open_dict(cfg):
            cfg.backend.update(connect)
        overrides = [*overrides, *(f"backend.{k}={json.dumps(v)}" for k, v in connect.items())]
    captured: dict[str, Any] = {}
    cpu0 = _cpu_s()
    try:
        manifest = execute(cfg, run_dir, choices, overrides,
                           lambda swarm: captured.update(backend=swarm.backend))
    finally:
        if launcher is not None:
            launcher.stop()
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


def boot_px4(cfg: Any, wait_s: float) -> Any:
    """Start the PX4 instances of a ``backend=px4`` config and return their launcher ``wait_s`` wall
    seconds later (the run then connects to them)."""
    from omegaconf import OmegaConf

    from swarmbox.hal.mavlink.frames import GeoFrame
    from swarmbox.hal.px4.params import Px4Params
    from swarmbox.hal.px4.sitl import SitlLauncher
    from swarmbox.run.mission import load

    params = OmegaConf.to_container(cfg.backend, resolve=True)
    for key in ("_target_", "name"):
        params.pop(key, None)
    p = Px4Params.from_kwargs({**params, "run_dir": None})
    mission = load(cfg)
    homes = [mission.initial_positions[i] for i in mission.drone_ids]
    launcher = SitlLauncher(p, homes, GeoFrame(p.origin_lat_deg, p.origin_lon_deg, p.origin_alt_m), None)
    launcher.start([])
    time.sleep(wait_s)
    return launcher


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


# ---- the experiment --------------------------------------------------------------------------------
def swarm_traffic_kb_s(run_dir: Path, sim_time_s: float) -> float:
    """Mean bytes the drone nodes send per second of mission time, per agent (KB/s)."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from swarmbox.record.broadcast import expand_broadcasts

    total = 0
    for i in DRONES:
        path = run_dir / "logs" / f"drone_{i}" / "messages.parquet"
        # one row per destination, whichever schema version wrote the file
        msgs = expand_broadcasts(pq.read_table(path, columns=["kind", "dst", "reason", "nbytes"]))
        total += int(pc.sum(msgs.filter(pc.equal(msgs["kind"], "send"))["nbytes"]).as_py() or 0)
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
    ap.add_argument("--px4-runs", type=int, default=1, help="PX4 repetitions (>= 2 gives the noise floor)")
    ap.add_argument("--px4-speed", type=float, default=1.0, help="PX4_SIM_SPEED_FACTOR of the PX4 runs")
    ap.add_argument("--px4-boot-wait", type=float, nargs="+", metavar="S",
                    help="wall s from booting PX4 to the mission, one per PX4 run (independent SIH noise)")
    ap.add_argument("--px4-only", action="store_true", help="no mavsim run (sim and PX4 only)")
    ap.add_argument("--reference", type=Path, default=REFERENCE,
                    help="recorded PX4 flights compared with the sim when no PX4 run is made")
    ap.add_argument("--save-reference", type=Path, help="keep this run's PX4 flights in this file")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "rq2_fidelity")
    ap.add_argument("--one", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        return run_one(Path(args.one[0]), args.one[2:], float(args.one[1]))
    out = args.out / time.strftime("%Y-%m-%d_%H-%M-%S")
    common = [*MISSION, *(CI_MISSION if args.ci else []), f"seed={args.seed}"]
    runs: dict[str, Path] = {}
    plan = backends(args.speed, args.px4_build, args.px4_runs, args.px4_speed, not args.px4_only)
    px4_labels = [label for label in plan if label.startswith("px4")]
    if args.px4_boot_wait and len(px4_labels) != len(args.px4_boot_wait):
        ap.error("--px4-boot-wait needs one value per PX4 run")
    waits = dict(zip(px4_labels, args.px4_boot_wait or [0.0] * len(px4_labels), strict=True))
    for label, extra in plan.items():
        run_dir = out / label
        print(f"[rq2] {label}: {' '.join(extra)}", flush=True)
        code = subprocess.call([sys.executable, __file__, "--one", str(run_dir), str(waits.get(label, 0.0)),
                                *common, *extra], cwd=ROOT)
        if code != 0:
            print(f"[rq2] {label} run failed (see {run_dir}/run.json)", file=sys.stderr)
            return 1
        runs[label] = run_dir
    code = report(runs, out) if len(runs) > 1 else 0
    return code or fidelity_report(runs, out, args)


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


def fidelity_report(runs: dict[str, Path], out: Path, args: argparse.Namespace) -> int:
    """The sim-vs-PX4 table (fidelity.table) and its overlay, against this run's PX4 flights or
    the recorded reference; optionally keep the PX4 flights as the new reference."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from fidelity import climb_s, overlay, table
    from flights import load_reference, run_flights, save_reference

    px4_dirs = {label: d for label, d in runs.items() if label.startswith("px4")}
    if px4_dirs:
        px4 = {label: run_flights(d) for label, d in px4_dirs.items()}
        source = "this run"
        if args.save_reference:
            waits = dict(zip(px4_dirs, args.px4_boot_wait or [0.0] * len(px4_dirs), strict=True))
            note = {"note": f"RQ2 formation on PX4 SITL at speed {args.px4_speed:g}; load after: "
                            f"{os.getloadavg()}", "sample_s": 0.05,
                    "runs": {label: {**{k: v for k, v in json.loads((d / "run.json").read_text()).items()
                                        if k in ("status", "sim_time_s", "wall_time_s", "overrides")},
                                     "boot_wait_s": waits.get(label, 0.0)}
                             for label, d in px4_dirs.items()}}
            save_reference(px4_dirs, args.save_reference, note)
    elif args.ci:
        print("[rq2] --ci flies a shorter mission than the recorded PX4 flights: no sim-vs-PX4 table")
        return 0
    elif args.reference.is_file():
        px4, source = load_reference(args.reference), str(args.reference.relative_to(ROOT))
    else:
        print(f"[rq2] no PX4 flights: give --px4-build or keep {args.reference}", file=sys.stderr)
        return 0
    import pandas as pd

    sims = {label: run_flights(runs[label]) for label in ("sim", "sim_px4") if label in runs}
    tab = pd.concat([table(f, px4).assign(backend=label) for label, f in sims.items()])
    tab = tab[["backend", *[c for c in tab.columns if c != "backend"]]]
    climbs = {label: [climb_s(f) for f in flights.values()] for label, flights in sims.items()}
    climbs["px4"] = [climb_s(f) for r in px4.values() for f in r.values()]
    tab.to_csv(out / "fidelity_px4.csv", index=False)
    text = (f"## Sim vs PX4 (PX4 flights: {source}; {len(px4)} run(s))\n\n" + markdown(tab.round(3))
            + "\n\nclimb to 90 % of the first altitude setpoint (s): "
            + "; ".join(f"{label} " + ", ".join(f"{v:.2f}" for v in vals) for label, vals in climbs.items())
            + "\n")
    (out / "fidelity_px4.md").write_text(text)
    best = sims.get("sim_px4", sims["sim"])
    overlay(best, px4).savefig(out / "fig3_sim_vs_px4.png", dpi=130, bbox_inches="tight")
    print(text + f"\n[rq2] written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
