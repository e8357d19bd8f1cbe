"""``python -m swarmbox.export RUN``: replay a run in Foxglove / PlotJuggler (MCAP) or Rerun (.rrd).

Examples::

    python -m swarmbox.export results/runs/<run>                         # both, into <run>/replay/
    python -m swarmbox.export results/runs/<run> --format rrd --from 20 --to 45
    python -m swarmbox.export results/runs/<run> --format mcap -o flight.mcap

Times are unified seconds since the run started (the analyzer's timeline). An existing file is
never overwritten unless ``--overwrite`` is given. Exit codes: 0 done, 2 bad input.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from swarmbox.analysis.load import RunLoadError
from swarmbox.analysis.replay import ReplayError, build_replay

FORMATS = {"mcap": ".mcap", "rrd": ".rrd"}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m swarmbox.export", description=__doc__.splitlines()[0])
    p.add_argument("run", type=Path, help="a run directory (holding run.json)")
    p.add_argument("--format", choices=["mcap", "rrd", "both"], default="both")
    p.add_argument("--from", dest="t_from", type=float, default=None, help="window start, s")
    p.add_argument("--to", dest="t_to", type=float, default=None, help="window end, s")
    p.add_argument("--window", type=float, default=0.5, help="bin of link and metric series, s")
    p.add_argument("-o", "--out", type=Path, default=None,
                   help="output file (one format) or directory (default: RUN/replay/)")
    p.add_argument("--overwrite", action="store_true", help="replace existing export files")
    return p


def _targets(args: argparse.Namespace) -> dict[str, Path]:
    formats = list(FORMATS) if args.format == "both" else [args.format]
    stem = "run"
    if args.t_from is not None or args.t_to is not None:
        lo = "start" if args.t_from is None else f"{args.t_from:g}"
        hi = "end" if args.t_to is None else f"{args.t_to:g}"
        stem += f"_{lo}-{hi}"
    if args.out is not None and args.out.suffix in FORMATS.values():
        if len(formats) > 1:
            raise ReplayError("-o names one file but --format both writes two: give a directory")
        return {formats[0]: args.out}
    folder = args.out if args.out is not None else args.run / "replay"
    return {f: folder / f"{stem}{FORMATS[f]}" for f in formats}


def export_main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        targets = _targets(args)
        existing = [str(p) for p in targets.values() if p.exists()]
        if existing and not args.overwrite:
            raise ReplayError(f"{', '.join(existing)} already exists (use --overwrite to replace)")
        replay = build_replay(args.run, t_from=args.t_from, t_to=args.t_to, window_s=args.window)
    except (RunLoadError, ReplayError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for fmt, path in targets.items():
        try:
            write = _writer(fmt)
        except ImportError as exc:
            print(f"error: {fmt} export needs the replay extra (pip install 'swarmbox[replay]'): {exc}",
                  file=sys.stderr)
            return 2
        path.parent.mkdir(parents=True, exist_ok=True)
        write(replay, path)
        print(f"{fmt}: {path}  ({replay.span[0]:.2f}-{replay.span[1]:.2f} s, {len(replay.drones)} drones)")
    return 0


def _writer(fmt: str):
    if fmt == "mcap":
        from swarmbox.analysis.export_mcap import export_mcap
        return export_mcap
    from swarmbox.analysis.export_rerun import export_rerun
    return export_rerun
