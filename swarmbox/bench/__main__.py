"""``python -m swarmbox.bench``: SwarmBox against the bare pymunk loop, interleaved, as a ratio table.

The bare loop (``floor.py``: N pymunk bodies, per-body Python PD at 40 Hz, 5 substeps) is the cheapest
honest Python loop that flies N drones. For each size, each round runs the bare loop and a SwarmBox
hover run (``python -m swarmbox.bench.hover``) back to back in fresh processes, alternating which goes
first, so that a shared machine's changing load hits both sides alike. The table reports median
real-time factors (simulated s per wall s of the tick loop) and the framework / bare-loop ratio of
agent-steps per second, which is the same ratio because both tick at 40 Hz. The load average is
printed before and after: ratios from a loaded machine are comparable, absolute rates are not.
The same ratio from CPU time is printed too (the tick loop's process CPU seconds; for the bare loop,
its whole-process CPU minus that of a one-tick run): on an oversubscribed machine it is the steadier
of the two.

    python -m swarmbox.bench                       # 5, 36, 200, 1000 drones, 2 rounds
    python -m swarmbox.bench --sizes 5 36 --rounds 3 --json results/bench.json
    python -m swarmbox.bench --jit always          # SwarmBox on the sim backend's compiled kernel
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_FLOOR = ROOT.parent / "shared" / "bench" / "floor.py"


def _run(cmd: list[str]) -> dict:
    out = subprocess.run(cmd, capture_output=True, text=True, check=False)
    lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"{' '.join(cmd)} failed (exit {out.returncode}): {out.stderr.strip()[-600:]}")
    return json.loads(lines[-1])


def measure(sizes: list[int], rounds: int, floor: Path, floor_s: float, hover_s: float,
            jit: str = "auto", core: str = "object", algo: str = "hover") -> list[dict]:
    """Every measurement, interleaved: per round, per size, bare loop and SwarmBox back to back."""
    env_python = sys.executable
    rows = []
    for r in range(rounds):
        for n in sizes:
            pair = [[env_python, str(floor), str(n), str(floor_s)],
                    [env_python, "-m", "swarmbox.bench.hover", str(n), "--hover-s", str(hover_s),
                     "--jit", jit, "--core", core, "--algo", algo]]
            if (r + sizes.index(n)) % 2:
                pair.reverse()
            for cmd in pair:
                row = _run(cmd)
                if row["system"] == "floor":
                    # the bare loop reports whole-process CPU; subtract a one-tick run's (imports, build)
                    setup = _run([env_python, str(floor), str(n), "0.025"])["cpu_s"]
                    row["loop_cpu_s"] = max(row["cpu_s"] - setup, 1e-9)
                row.update(round=r, load1=os.getloadavg()[0])
                print(json.dumps(row), file=sys.stderr, flush=True)
                rows.append(row)
    return rows


def table(rows: list[dict], sizes: list[int]) -> list[dict]:
    """Per size: median RTF of each side and the framework / bare-loop ratio."""
    out = []
    for n in sizes:
        floor = [r["rtf"] for r in rows if r["n"] == n and r["system"] == "floor"]
        box = [r["rtf"] for r in rows if r["n"] == n and r["system"] == "swarmbox"]
        f, b = statistics.median(floor), statistics.median(box)
        f_cpu = statistics.median(r["sim_s"] / r["loop_cpu_s"] for r in rows
                                  if r["n"] == n and r["system"] == "floor")
        b_cpu = statistics.median(r["sim_s"] / r["loop_cpu_s"] for r in rows
                                  if r["n"] == n and r["system"] == "swarmbox")
        out.append({"drones": n, "bare_rtf": f, "swarmbox_rtf": b, "ratio": b / f,
                    "ratio_min": min(box) / max(floor), "ratio_max": max(box) / min(floor),
                    "bare_cpu_rtf": f_cpu, "swarmbox_cpu_rtf": b_cpu, "cpu_ratio": b_cpu / f_cpu,
                    "rounds": len(box)})
    return out


def markdown(summary: list[dict], load: tuple[float, float]) -> str:
    lines = ["| drones | bare loop RTF | SwarmBox hover RTF | framework / bare loop (range) "
             "| CPU-time RTF bare / SwarmBox | CPU-time ratio |", "|---|---|---|---|---|---|"]
    for s in summary:
        lines.append(f"| {s['drones']} | {s['bare_rtf']:.3g} | {s['swarmbox_rtf']:.3g} | "
                     f"{s['ratio']:.2f} ({s['ratio_min']:.2f}-{s['ratio_max']:.2f}) | "
                     f"{s['bare_cpu_rtf']:.3g} / {s['swarmbox_cpu_rtf']:.3g} | {s['cpu_ratio']:.2f} |")
    lines.append(f"\nload average (1 min): {load[0]:.2f} before, {load[1]:.2f} after; {os.cpu_count()} cores")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m swarmbox.bench", description=(
        "SwarmBox vs the bare pymunk loop, interleaved; prints the ratio table."))
    p.add_argument("--sizes", type=int, nargs="+", default=[5, 36, 200, 1000], help="swarm sizes")
    p.add_argument("--rounds", type=int, default=2, help="measurements per size and side (2)")
    p.add_argument("--floor", type=Path, default=DEFAULT_FLOOR,
                   help=f"the bare loop script ({DEFAULT_FLOOR})")
    p.add_argument("--floor-s", type=float, default=10.0, help="simulated seconds of the bare loop (10)")
    p.add_argument("--hover-s", type=float, default=10.0, help="SwarmBox hover time at altitude, s (10)")
    p.add_argument("--jit", choices=["auto", "always", "never"], default="auto",
                   help="backend.jit of the SwarmBox runs (always: the compiled kernel of long runs, loaded "
                        "before the loop; auto: these short runs stay on numpy)")
    p.add_argument("--core", choices=["object", "fleet"], default="object",
                   help="run.core of the SwarmBox runs: per-drone node objects, or the fleet's arrays")
    p.add_argument("--algo", choices=["hover", "hover_batch"], default="hover",
                   help="the SwarmBox runs' algorithm: per-drone hover or its batch port (hover)")
    p.add_argument("--json", type=Path, help="also write every measurement and the table here")
    args = p.parse_args(argv)
    if not args.floor.is_file():
        print(f"error: bare loop script {args.floor} not found (give it with --floor)", file=sys.stderr)
        return 2
    if args.rounds < 1 or any(n < 1 for n in args.sizes):
        print("error: --rounds and every size must be >= 1", file=sys.stderr)
        return 2
    before = os.getloadavg()[0]
    rows = measure(args.sizes, args.rounds, args.floor, args.floor_s, args.hover_s, args.jit, args.core,
                   args.algo)
    summary = table(rows, args.sizes)
    after = os.getloadavg()[0]
    print(markdown(summary, (before, after)))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"load1": [before, after], "cores": os.cpu_count(), "table": summary,
                                         "measurements": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
