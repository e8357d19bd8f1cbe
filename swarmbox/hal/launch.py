"""What every launcher of vehicle processes (PX4 SITL instances, mavsim vehicles) shares."""

from __future__ import annotations

import subprocess
from collections.abc import Mapping


class ProcessSet:
    """Exit checks over a launcher's vehicle processes.

    Subclasses set ``procs`` (one process per vehicle, in vehicle order), ``_reported`` (a set) and
    ``what`` (how a process is named in messages), and may override ``_tail`` (its recent output).
    """

    what = "vehicle process"
    procs: list[subprocess.Popen[bytes]]
    _reported: set[int]

    def _tail(self, i: int) -> str:
        return ""

    def check(self) -> None:
        """Raise if a vehicle process has exited, with the end of its output."""
        for i, proc in enumerate(self.procs):
            if proc.poll() is not None:
                raise RuntimeError(f"{self.what} {i} exited with code {proc.returncode}:\n{self._tail(i)}")

    def poll_exits(self) -> list[tuple[int, int]]:
        """(vehicle, exit code) of every process that exited since the last call."""
        out = []
        for i, proc in enumerate(self.procs):
            if i not in self._reported and proc.poll() is not None:
                self._reported.add(i)
                out.append((i, int(proc.returncode)))
        return out


#: names of further key variables (comma-separated), set by the process that handed the keys over
KEY_VARS = "SWARMBOX_KEY_VARS"


def without_keys(env: Mapping[str, str]) -> dict[str, str]:
    """``env`` without SwarmBox's key variables (``SWARMBOX_*_KEY`` and those ``SWARMBOX_KEY_VARS``
    names, e.g. a custom ``run.net.key_env``): a vehicle or helper process is handed only the key it
    needs, explicitly, never the swarm key its parent may hold."""
    named = {n for n in env.get(KEY_VARS, "").split(",") if n}
    return {k: v for k, v in env.items()
            if k not in named and not (k.startswith("SWARMBOX_") and k.endswith("_KEY"))}
