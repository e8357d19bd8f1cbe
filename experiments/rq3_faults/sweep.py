"""Run plans of the RQ3 study and of the diagnosis benchmark, and their execution.

Every run is one configuration of ``python -m swarmbox.run`` (its overrides are listed in
``plan.csv``, so any run can be replayed on its own). Runs execute in-process, one at a time
(``--jobs`` for more); a run directory that already holds a finished run is kept, one without
``run.json`` (interrupted) is flown again, so an interrupted sweep resumes where it stopped and a
finished one flies nothing. After each run its diagnosis rows
(:func:`swarmbox.analysis.detection.evaluate_run`) are written next to it as ``diagnosis.parquet``.

    python experiments/rq3_faults/sweep.py rq3   OUT      # the paper's 135 runs
    python experiments/rq3_faults/sweep.py bench OUT      # the detection benchmark (1,894 runs)
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
#: The benchmark's magnitudes around the default detector's floor (fault model -> override, values):
#: the smallest of the earlier benchmark's four that any setting found, and the two above it.
MAGNITUDES = {
    "gps_drift": ("fault.rate_m_s", (0.5, 1.0, 2.0)),
    "gps_bias": ("fault.bias_ned_m", ([1.0, 0, 0], [2.0, 0, 0], [4.0, 0, 0])),
    "gps_noise": ("fault.noise_scale", (5.0, 10.0, 20.0)),
    "latency": ("fault.latency_ms", (0.5, 1.0, 2.0)),
    "packet_loss": ("fault.loss_prob", (0.02, 0.05, 0.1)),
    "burst_loss": ("fault.p_enter_burst", (0.005, 0.01, 0.02)),
}
WINDOW = ("fault.onset_s=25.0", "fault.duration_s=20.0")
#: The benchmark flies the RQ3 circle at the same speed on half the radius (one lap in ~24 s), and
#: the fault is on from 12 s to 27 s: half the simulation of the RQ3 runs.
SHORT = ("algo.params.radius_m=25.0", "algo.params.angular_rate_rad_s=0.26667")
BENCH_WINDOW = ("fault.onset_s=12.0", "fault.duration_s=15.0")
#: With 36 drones (four times the simulation and analysis per run) the paper's three faults at the
#: 9-drone default floor, default detector only (no calibration seeds).
MAGNITUDES_36 = {"gps_drift": (1.0,), "latency": (1.0,), "packet_loss": (0.05,)}
#: Two faults in one run, on two different drones, over the same window (every truth is scored).
COMPOSED = {"drift+latency": (("gps_drift", "rate_m_s", 1.0), ("latency", "latency_ms", 2.0)),
            "bias+loss": (("gps_bias", "bias_ned_m", [2.0, 0, 0]), ("packet_loss", "loss_prob", 0.1)),
            "noise+burst": (("gps_noise", "noise_scale", 20.0), ("burst_loss", "p_enter_burst", 0.02))}
#: Faults on every drone (or on the ground, -1) at once: one swarm-wide truth per run, detected by an
#: alarm on any drone. A common-mode fault moves every drone alike, which a cross-swarm comparison
#: cannot see; independent noise on every drone it can.
SWARM_WIDE = {"gps_noise_all": ("gps_noise", "fault.noise_scale=20.0", "all"),
              "gps_drift_all": ("gps_drift", "fault.rate_m_s=1.0", "all"),
              "latency_all": ("latency", "fault.latency_ms=5.0", "all"),
              "packet_loss_all": ("packet_loss", "fault.loss_prob=0.1", "all"),
              "latency_ground": ("latency", "fault.latency_ms=20.0", "ground")}
NETWORKS = {"ideal": ("network=ideal", "network.latency_ms=1.0", "network.jitter_ms=1.0"),
            "wifi": ("network=wifi",)}
SIZES = {9: "mission=formation9", 36: "mission=formation36"}
RQ3 = {"drift": ("gps_drift", "fault.rate_m_s", (1.0, 2.0, 3.0, 4.0, 5.0)),
       "latency": ("latency", "fault.latency_ms", (5.0, 10.0, 15.0, 20.0, 25.0)),
       "loss": ("packet_loss", "fault.loss_prob", (0.1, 0.2, 0.3, 0.4, 0.5))}
#: Seeds. Calibration seeds choose the tuned detector setting per cell; report seeds (never flown
#: before this benchmark, and not the seeds the default thresholds were settled on) measure it.
CALIBRATION_FAULTY = range(0, 4)
CALIBRATION_HEALTHY = range(100, 108)
REPORT_FAULTY_FROM = 1000
REPORT_HEALTHY_FROM = 2000
#: Report seeds per part of the plan (``--reps`` overrides ``single``).
REPS = {"single": 36, "healthy": 36, "composed": 20, "swarm": 15, "single36": 15, "healthy36": 3}


def execute(run_dir: Path, overrides: list[str]) -> None:
    """Compose and run one configuration exactly as ``python -m swarmbox.run <overrides>`` does."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf, open_dict

    from swarmbox.run.config import register
    from swarmbox.run.runner import execute as run
    from swarmbox.run.runner import run_choices

    register()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(ROOT / "swarmbox" / "conf"), version_base="1.3"):
        cfg = compose("config", overrides=list(overrides), return_hydra_config=True)
    choices = run_choices(cfg, OmegaConf.to_container(cfg.hydra.runtime.choices))
    with open_dict(cfg):
        del cfg["hydra"]
    run(cfg, run_dir, choices, list(overrides))


def _value(v) -> str:
    return f"[{','.join(str(float(x)) for x in v)}]" if isinstance(v, list | tuple) else str(v)


def rq3_plan() -> pd.DataFrame:
    """The paper's study: 3 faults x 5 magnitudes x 9 target drones, seed 0, 9 drones, base network."""
    rows = []
    for kind, (model, key, values) in RQ3.items():
        for i, v in enumerate(values):
            for target in range(9):
                rows.append(("rq3", "report", 0, f"{kind}/m{i}_t{target}",
                             " ".join(["+experiment=rq3_bench", f"fault={model}", f"{key}={v}",
                                       f"fault.targets=[{target}]", *WINDOW, *NETWORKS["ideal"], SIZES[9],
                                       "seed=0"])))
    return pd.DataFrame(rows, columns=["part", "split", "seed", "run", "overrides"])


def _target(name: str, n: int, k: int = 1) -> list[int]:
    """``k`` distinct target drones for a run, drawn from a generator seeded by the run's name: the
    same run always gets the same targets, whatever else the plan holds."""
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    return sorted(int(x) for x in rng.choice(n, size=k, replace=False))


def calibration_seeds() -> set[int]:
    """Every seed whose runs may choose a detector setting (the report seeds are all others)."""
    return {*CALIBRATION_FAULTY, *CALIBRATION_HEALTHY}


def _seeds(part: str, reps: dict[str, int], calibrated: bool) -> list[tuple[str, int]]:
    healthy = part.startswith("healthy")
    first = REPORT_HEALTHY_FROM if healthy else REPORT_FAULTY_FROM
    calib = (CALIBRATION_HEALTHY if healthy else CALIBRATION_FAULTY) if calibrated else ()
    return [("calibration", s) for s in calib] + [("report", first + r) for r in range(reps[part])]


def _single(n: int, net: str, common: list[str], reps: dict[str, int]) -> list[tuple]:
    rows = []
    part = "single" if n == 9 else "single36"
    for model, (key, values) in MAGNITUDES.items():
        for i, v in enumerate(values):
            if n == 36 and v not in MAGNITUDES_36.get(model, ()):
                continue
            for split, seed in _seeds(part, reps, calibrated=n == 9):
                name = f"n{n}/{net}/single/{model}/m{i}/s{seed}"
                rows.append((part, split, seed, name, [*common, f"fault={model}", f"{key}={_value(v)}",
                                                      f"fault.targets=[{_target(name, n)[0]}]",
                                                      *BENCH_WINDOW, f"seed={seed}"]))
    return rows


def _composed(net: str, common: list[str], reps: dict[str, int]) -> list[tuple]:
    rows = []
    for combo, faults in COMPOSED.items():
        for split, seed in _seeds("composed", reps, calibrated=False):
            name = f"n9/{net}/composed/{combo}/s{seed}"
            targets = _target(name, 9, k=2)
            over = [f"fault=[{','.join(m for m, _, _ in faults)}]"]
            for (model, key, v), t in zip(faults, targets, strict=True):
                over += [f"fault.{model}.targets=[{t}]", f"fault.{model}.{key}={_value(v)}"]
            rows.append(("composed", split, seed, name, [*common, *over, *BENCH_WINDOW, f"seed={seed}"]))
    return rows


def _swarm_wide(net: str, common: list[str], reps: dict[str, int]) -> list[tuple]:
    rows = []
    for kind, (model, magnitude, where) in SWARM_WIDE.items():
        targets = "[-1]" if where == "ground" else f"[{','.join(str(d) for d in range(9))}]"
        for split, seed in _seeds("swarm", reps, calibrated=False):
            rows.append(("swarm", split, seed, f"n9/{net}/swarm/{kind}/s{seed}",
                         [*common, f"fault={model}", magnitude, f"fault.targets={targets}", *BENCH_WINDOW,
                          f"seed={seed}"]))
    return rows


def bench_plan(reps: dict[str, int] | None = None) -> pd.DataFrame:
    """The diagnosis benchmark, one row per run (part, split, seed, run name, overrides). 9 drones:
    every fault model at three magnitudes, calibration and report seeds, healthy runs, composed and
    swarm-wide faults; 36 drones: three faults at one magnitude and healthy runs, report seeds. Both
    networks. Deterministic: the same ``reps`` give the same plan, in an order where every cell gains
    its n-th seed before any gains its (n+1)-th, so a sweep cut short still covers every cell."""
    reps = {**REPS, **(reps or {})}
    rows = []
    for n, mission in SIZES.items():
        for net, net_over in NETWORKS.items():
            common = ["+experiment=rq3_bench", *SHORT, *net_over, mission]
            healthy = "healthy" if n == 9 else "healthy36"
            for split, seed in _seeds(healthy, reps, calibrated=n == 9):
                rows.append((healthy, split, seed, f"n{n}/{net}/none/s{seed}",
                             [*common, "fault=none", f"seed={seed}"]))
            rows += _single(n, net, common, reps)
            if n == 9:
                rows += _composed(net, common, reps) + _swarm_wide(net, common, reps)
    plan = pd.DataFrame(rows, columns=["part", "split", "seed", "run", "overrides"])
    plan["overrides"] = [" ".join(o) for o in plan["overrides"]]
    order = plan.assign(_split=plan["split"] != "calibration", _seed=plan["seed"] % 1000)
    order = order.sort_values(["_split", "_seed", "run"], kind="stable")
    return order[plan.columns].reset_index(drop=True)


def run_one(out: Path, name: str, overrides: list[str]) -> str:
    """Execute one planned run unless it finished before, and diagnose it unless it was; returns a
    status line that starts with ``flown`` or ``kept``. A directory without ``run.json`` is a run
    that was interrupted: it holds no result, and is removed and flown again."""
    from swarmbox.analysis.detection import default_settings, evaluate_run

    run_dir = out / name
    t0 = time.time()
    flown = not (run_dir / "run.json").exists()
    if flown:
        shutil.rmtree(run_dir, ignore_errors=True)
        execute(run_dir, overrides)
    status = json.loads((run_dir / "run.json").read_text())["status"]
    t1 = time.time()
    if not (run_dir / "diagnosis.parquet").exists():
        rows = evaluate_run(run_dir, default_settings())
        rows.to_parquet(run_dir / "diagnosis.parquet.tmp", index=False)
        (run_dir / "diagnosis.parquet.tmp").rename(run_dir / "diagnosis.parquet")
    return f"{'flown' if flown else 'kept'} {name} {status} run {t1 - t0:.1f}s diag {time.time() - t1:.1f}s"


def collect(out: Path) -> pd.DataFrame:
    """Every run's diagnosis rows below ``out``, each with its run's ``status`` (run.json) and, when
    ``out/plan.csv`` lists the run, its plan ``part`` and ``split``."""
    parts = []
    for path in sorted(out.rglob("diagnosis.parquet")):
        status = json.loads((path.parent / "run.json").read_text())["status"]
        name = path.parent.relative_to(out).as_posix()
        parts.append(pd.read_parquet(path).assign(run=name, status=status))
    rows = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()
    if len(rows) and (out / "plan.csv").is_file():
        plan = pd.read_csv(out / "plan.csv")[["run", "part", "split"]]
        rows = rows.merge(plan, on="run", how="left")
    return rows


def sweep(plan: pd.DataFrame, out: Path, jobs: int = 1) -> list[str]:
    """Write ``out/plan.csv`` and execute every planned run that has not finished (in plan order);
    the status lines, one per run."""
    out.mkdir(parents=True, exist_ok=True)
    plan.to_csv(out / "plan.csv.tmp", index=False)
    (out / "plan.csv.tmp").replace(out / "plan.csv")
    start = time.time()
    lines = []
    if jobs == 1:
        todo = (run_one(out, n, o.split()) for n, o in zip(plan["run"], plan["overrides"], strict=True))
    else:
        from joblib import Parallel, delayed

        todo = Parallel(n_jobs=jobs, return_as="generator")(
            delayed(run_one)(out, n, o.split()) for n, o in zip(plan["run"], plan["overrides"], strict=True))
    for line in todo:
        lines.append(line)
        print(f"[{time.time() - start:7.1f}s] {line}", flush=True)
    flown = sum(line.startswith("flown") for line in lines)
    print(f"{len(plan)} runs planned, {flown} flown, in {time.time() - start:.0f} s wall", flush=True)
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("which", choices=["rq3", "bench"])
    p.add_argument("out", type=Path)
    p.add_argument("--jobs", type=int, default=1, help="runs at a time (1)")
    p.add_argument("--reps", type=int, default=REPS["single"],
                   help=f"report seeds per single-fault cell with 9 drones ({REPS['single']})")
    p.add_argument("--plan-only", action="store_true", help="write plan.csv and stop")
    args = p.parse_args(argv)
    plan = rq3_plan() if args.which == "rq3" else bench_plan({"single": args.reps})
    if args.plan_only:
        args.out.mkdir(parents=True, exist_ok=True)
        plan.to_csv(args.out / "plan.csv", index=False)
        print(f"{len(plan)} runs planned in {args.out / 'plan.csv'}")
        return 0
    sweep(plan, args.out, args.jobs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
