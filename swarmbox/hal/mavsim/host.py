"""Many mavsim vehicles in one process: ``python -m swarmbox.hal.mavsim.host --spec SPEC.json``.

Each vehicle is what ``python -m swarmbox.hal.mavsim.process`` runs alone (its own simulation,
commander, system id and UDP socket, so a bridge cannot tell the difference); the host steps them
all on one wall-clock pacing loop. On a small machine this is what makes a large swarm possible:
36 agents need 36 + 1 processes instead of 72, and one interpreter's memory instead of 36. The
vehicles must share speed and physics step. ``SPEC.json`` is ``{"vehicles": [[arg, ...], ...]}``,
each list the arguments of one ``mavsim.process`` (``--instance``, ``--port-plan REMOTE:0``, ...).
The process ends on SIGTERM/SIGINT, when ``--parent-pid`` is gone, or after ``--max-wall-s``.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from swarmbox.hal.mavsim.process import MAX_CATCH_UP_STEPS, MavsimProgram, _gone, parse_args


class Host:
    """Vehicles stepped together: receive all, step all to the wall clock, send all, wait on all sockets."""

    def __init__(self, programs: list[MavsimProgram], parent_pid: int | None, max_wall_s: float) -> None:
        if not programs:
            raise ValueError("a mavsim host needs at least one vehicle")
        speeds = {p.args.speed for p in programs}
        ticks = {p.args.tick_s for p in programs}
        if len(speeds) != 1 or len(ticks) != 1:
            raise ValueError(f"the vehicles of one host share speed and tick, got {speeds} and {ticks}")
        self.programs, self.parent_pid, self.max_wall_s = programs, parent_pid, max_wall_s
        self.speed, self.dt = speeds.pop(), ticks.pop()
        self.stop = False

    def run(self) -> int:
        progs, dt, speed = self.programs, self.dt, self.speed
        clock = progs[0].sim                 # every vehicle steps in lockstep: one clock for all
        socks = [p.link.sock for p in progs]
        wall0 = start = time.monotonic()
        direct_child = self.parent_pid is not None and os.getppid() == self.parent_pid
        while not self.stop:
            now = time.monotonic()
            if now - start > self.max_wall_s or (self.parent_pid and _gone(self.parent_pid, direct_child)):
                break
            for p in progs:
                p.receive()
            target_s, steps = (now - wall0) * speed, 0
            while clock.t_s + dt <= target_s + 1e-9 and steps < MAX_CATCH_UP_STEPS:
                for p in progs:
                    p.commander.step(dt)
                    p.send_streams()
                steps += 1
            if steps == MAX_CATCH_UP_STEPS:   # overloaded: slow the simulation down, never skip
                wall0 = time.monotonic() - clock.t_s / speed
            wait_s = wall0 + (clock.t_s + dt) / speed - time.monotonic()
            if wait_s > 0:
                select.select(socks, [], [], min(wait_s, 0.1))
        for p in progs:
            p.link.close()
        return 0


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m swarmbox.hal.mavsim.host",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--spec", type=Path, required=True)
    ap.add_argument("--parent-pid", type=int, default=None)
    ap.add_argument("--max-wall-s", type=float, default=3600.0)
    args = ap.parse_args(argv)
    try:
        spec = json.loads(args.spec.read_text())
        programs = [MavsimProgram(parse_args(v)) for v in spec["vehicles"]]
        host = Host(programs, args.parent_pid, args.max_wall_s)
    except (ValueError, TypeError, KeyError, OSError) as exc:
        print(f"mavsim host: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2

    def _stop(_signum: int, _frame: object) -> None:
        host.stop = True

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    for p in host.programs:
        print(f"mavsim host: system {p.system_id} on 127.0.0.1:{p.link.local_port} -> {p.link.peer[1]}, "
              f"signing {'on' if p.signed else 'off'}", file=sys.stderr, flush=True)
    code = host.run()
    rejected = sum(p.decoder.signature_rejected for p in host.programs)
    print(f"mavsim host: {len(host.programs)} vehicles stopped at t={host.programs[0].sim.t_s:.1f} s (sim), "
          f"unsigned or wrongly signed {rejected} packets", file=sys.stderr, flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
