"""N real PX4 SITL instances at a speed factor: achieved speed, CPU per instance and of the client.

Flies ``algo`` (default: the 9-drone RQ3 formation) on ``n`` PX4 SIH instances launched by the
``px4`` backend at ``run.speed=speed``, once per variant, interleaved over ``reps``:

- ``needed``: the bridge's default, only the streams it uses (``message_rates_hz``) and every other
  stream asked to stop (``silence_unrequested``);
- ``all``: PX4's default stream set left on (``silence_unrequested=false``), what a client that
  does not manage streams receives.

While a run flies, ``/proc`` is sampled every second for the client (the run's Python process) and
each PX4 process: CPU seconds over wall seconds (1.0 = one core). Per run it records the load
average before and after, the run loop's real-time factor (``run.json``), PX4's own achieved speed
against the wall clock (the boot clock the bridge fitted, PX4 boot time against run time in
``logs/drone_i/ulog.json``, times the run loop's real-time factor)
and the packets each vehicle's link received per second of run time (``link/stats`` events).

    python experiments/px4_scale/run.py --out /tmp/px4_scale            # 9 x 2x, both variants, 1 rep
    python experiments/px4_scale/run.py --n 4 --speed 1 --reps 3 --out ...

Writes ``<out>/runs.csv`` (one row per run) and ``<out>/instances.csv`` (one row per PX4 process)
and prints a summary. The machine's other load changes every figure: compare variants of one
invocation (interleaved), and read them with the load average beside them.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
VARIANTS = {"needed": [], "all": ["backend.silence_unrequested=false"]}
TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float | None:
    """utime + stime of a process (s), None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def px4_pids(first: int, n: int) -> dict[int, int]:
    """PX4 instance number -> pid, for the instances of this measurement."""
    found = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            args = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if len(args) > 2 and args[0].endswith(b"/px4") and args[1] == b"-i":
            inst = int(args[2])
            if first <= inst < first + n:
                found[inst] = int(proc.name)
    return found


class Tracker:
    """CPU seconds of a process between its first and last sample, over that wall time."""

    def __init__(self) -> None:
        self.first: dict[int, tuple[float, float]] = {}
        self.last: dict[int, tuple[float, float]] = {}

    def sample(self, key: int, pid: int, now: float) -> None:
        cpu = cpu_seconds(pid)
        if cpu is None:
            return
        self.first.setdefault(key, (now, cpu))
        self.last[key] = (now, cpu)

    def share(self, key: int) -> float:
        (t0, c0), (t1, c1) = self.first[key], self.last[key]
        return (c1 - c0) / (t1 - t0) if t1 > t0 else float("nan")


def link_rate(run_dir: Path, drone: int) -> float:
    """Packets received per run second by the drone's link, over its last link/stats interval."""
    import pandas as pd

    ev = pd.read_parquet(run_dir / "logs" / f"drone_{drone}" / "events.parquet")
    stats = ev[(ev["kind"] == "link") & (ev["name"] == "stats")]
    if len(stats) < 2:
        return float("nan")
    a, b = (json.loads(stats["data"].iloc[k]) for k in (-2, -1))
    return (b["rx_packets"] - a["rx_packets"]) / (stats["t_s"].iloc[-1] - stats["t_s"].iloc[-2])


def px4_speed(run_dir: Path, drone: int, run_factor: float) -> float:
    """PX4's achieved speed against the wall clock: run time advances ``b`` s per PX4 boot second
    (the bridge's boot-clock fit) and the run loop ``run_factor`` s per wall second."""
    index = run_dir / "logs" / f"drone_{drone}" / "ulog.json"
    if not index.is_file() or not run_factor:
        return float("nan")
    return run_factor / json.loads(index.read_text())["clock"]["b"]


def fly(args: argparse.Namespace, variant: str, rep: int) -> tuple[dict, list[dict]]:
    run_dir = Path(args.out) / f"{variant}_{rep}"
    cmd = [sys.executable, "-m", "swarmbox.run", f"algo={args.algo}", "backend=px4",
           f"run.speed={args.speed:g}", f"backend.sitl.first_instance={args.first_instance}",
           f"run.out_dir={run_dir}", *VARIANTS[variant], *args.override]
    load_before = os.getloadavg()
    started = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    client, instances = Tracker(), Tracker()
    while proc.poll() is None:
        now = time.monotonic()
        client.sample(0, proc.pid, now)
        for inst, pid in px4_pids(args.first_instance, args.n).items():
            instances.sample(inst, pid, now)
        time.sleep(1.0)
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    wall = time.monotonic() - started
    manifest = json.loads((run_dir / "run.json").read_text()) if (run_dir / "run.json").is_file() else {}
    shares = {inst: instances.share(inst) for inst in instances.first}
    rtf = manifest.get("real_time_factor") or 0.0
    row = {"variant": variant, "rep": rep, "n": args.n, "speed": args.speed,
           "status": manifest.get("status"),
           "reason": manifest.get("reason") or err.strip().splitlines()[-1:] or "",
           "load_before": round(load_before[0], 2), "load_after": round(os.getloadavg()[0], 2),
           "wall_s": round(wall, 1), "sim_s": manifest.get("sim_time_s"),
           "run_real_time_factor": manifest.get("real_time_factor"),
           "client_cpu": round(client.share(0), 3) if client.first else float("nan"),
           "px4_cpu_total": round(sum(shares.values()), 3),
           "px4_cpu_mean": round(float(np.mean(list(shares.values()))), 3) if shares else float("nan"),
           "px4_speed_min": round(min((px4_speed(run_dir, i, rtf) for i in range(args.n)),
                                      default=float("nan")), 3),
           "rx_packets_per_s_mean": round(float(np.nanmean([link_rate(run_dir, i) for i in range(args.n)])),
                                          1) if manifest else float("nan")}
    per = [{"variant": variant, "rep": rep, "instance": inst, "cpu": round(share, 3),
            "px4_speed": round(px4_speed(run_dir, inst - args.first_instance, rtf), 3)}
           for inst, share in sorted(shares.items())]
    return row, per


def write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        return
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=9, help="vehicles (must match the algorithm's mission)")
    ap.add_argument("--algo", default="formation9")
    ap.add_argument("--speed", type=float, default=2.0)
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--variants", default="needed,all")
    ap.add_argument("--first-instance", type=int, default=20, help="PX4 instance numbers start here")
    ap.add_argument("--out", required=True)
    ap.add_argument("override", nargs="*", help="extra Hydra overrides for every run")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, per = [], []
    for rep in range(args.reps):
        for variant in args.variants.split(","):
            row, inst = fly(args, variant, rep)
            rows.append(row)
            per.extend(inst)
            print(json.dumps(row), flush=True)
            write_csv(out / "runs.csv", rows)
            write_csv(out / "instances.csv", per)
    return 0 if all(r["status"] == "ok" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
