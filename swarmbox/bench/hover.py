"""One hover run of N drones on a grid, in this process; prints its ``run.json`` figures as JSON.

``python -m swarmbox.bench.hover N [--hover-s S] [--algo hover|hover_batch] [--out DIR]`` — the
SwarmBox side of the interleaved benchmark. The grid and the run are built exactly as ``python -m
swarmbox.run algo=hover mission=hover`` would build them, with ``initial_positions`` replaced by an
N-drone grid.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

SPACING_M = 5.0


def grid(n: int, spacing_m: float = SPACING_M) -> dict[int, list[float]]:
    """``n`` drone homes on a square grid, ``spacing_m`` apart."""
    side = math.ceil(math.sqrt(n))
    return {i: [spacing_m * (i % side), spacing_m * (i // side)] for i in range(n)}


def compose(n: int, hover_s: float, extra: Sequence[str] = (), algo: str = "hover"):
    """The run config of an N-drone hover, composed like the command line does."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf, open_dict

    from swarmbox.run.config import register
    from swarmbox.run.runner import run_choices

    register()
    conf = Path(__file__).resolve().parents[1] / "conf"
    overrides = [f"algo={algo}", "mission=hover", f"algo.params.hover_s={hover_s}", "run.progress=false",
                 *extra]
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(conf), version_base="1.3"):
        cfg = hydra_compose("config", overrides=overrides, return_hydra_config=True)
    choices = run_choices(cfg, OmegaConf.to_container(cfg.hydra.runtime.choices))
    with open_dict(cfg):
        del cfg["hydra"]
        cfg.mission.initial_positions = homes = grid(n)
        cfg.mission.swarm_size = n
        # a large grid reaches past the default geofence (500 m at 10,000 drones): widen it to the grid
        reach = max(math.hypot(*home) for home in homes.values()) + SPACING_M
        if reach > cfg.run.safety.geofence_radius_m:
            cfg.run.safety.geofence_radius_m = float(math.ceil(reach))
    return cfg, choices, overrides


def hover_run(n: int, hover_s: float, run_dir: Path, extra: Sequence[str] = (), algo: str = "hover") -> dict:
    """Execute the run into ``run_dir`` (``extra``: more overrides); returns the manifest plus the
    whole call's wall time."""
    from swarmbox.run.runner import execute

    cfg, choices, overrides = compose(n, hover_s, list(extra), algo)
    cpu: dict[str, float] = {}

    def measure_loop(swarm) -> None:
        # CPU seconds of the tick loop, every thread of the process (the log writer's work counts):
        # unlike wall time, it barely moves when other jobs share the cores.
        run = swarm.run

        def measured(*args, **kwargs):
            start_cpu = time.process_time()
            try:
                return run(*args, **kwargs)
            finally:
                cpu["loop"] = time.process_time() - start_cpu

        swarm.run = measured

    start = time.perf_counter()
    manifest = execute(cfg, run_dir, choices, overrides, prepare=measure_loop)
    manifest["total_wall_s"] = time.perf_counter() - start
    manifest["loop_cpu_s"] = cpu.get("loop")
    return manifest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m swarmbox.bench.hover", description=__doc__.splitlines()[0])
    p.add_argument("n", type=int, help="number of drones")
    p.add_argument("--hover-s", type=float, default=10.0, help="time at altitude, s (10)")
    p.add_argument("--out", type=Path, help="keep the run here (default: a temporary directory)")
    p.add_argument("--jit", choices=["auto", "always", "never"], default="auto",
                   help="backend.jit: the sim backend's compiled kernel (auto: as a run of that length)")
    p.add_argument("--algo", choices=["hover", "hover_batch"], default="hover",
                   help="the per-drone hover or its batch port (the same flight and logs)")
    p.add_argument("--core", choices=["object", "fleet"], default="object",
                   help="run.core: one node object per drone, or the fleet's arrays (object)")
    args = p.parse_args(argv)
    if args.n < 1:
        p.error(f"n must be >= 1, got {args.n}")
    tmp = None if args.out else Path(tempfile.mkdtemp(prefix="swarmbox-bench-"))
    try:
        m = hover_run(args.n, args.hover_s, args.out or tmp / "run",
                      [f"backend.jit={args.jit}", f"run.core={args.core}"], args.algo)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    ticks, wall = m["ticks"], m["wall_time_s"]
    print(json.dumps({"system": "swarmbox", "algo": args.algo, "core": args.core, "n": args.n,
                      "status": m["status"],
                      "sim_s": m["sim_time_s"],
                      "loop_wall_s": round(wall, 4), "rtf": round(m["real_time_factor"], 3),
                      "agent_steps_per_s": round(args.n * ticks / wall) if wall > 0 else None,
                      "loop_cpu_s": round(m["loop_cpu_s"] or float("nan"), 4),
                      "total_wall_s": round(m["total_wall_s"], 3)}))
    return 0 if m["status"] == "ok" else 1


if __name__ == "__main__":
    sys.exit(main())
