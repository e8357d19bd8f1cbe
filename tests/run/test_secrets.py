"""No key reaches a file, the console or a process that does not need it.

Every file a run or sweep writes, and everything it prints, is searched for the key values given on
the command line and in the environment; the environment of every process a processes run starts
is read from /proc while it flies.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CLI_KEY = "cli-swarm-key-0123456789abcdef"
ENV_KEY = "env-swarm-key-fedcba9876543210"
SIGN_KEY = "mavlink-signing-passphrase-42"
TYPO_KEY = "typo-key-value-5555555555"


def swarmbox(*args: str, wait: bool = True):
    env = dict(os.environ, PYTHONPATH=str(ROOT), SWARMBOX_NET_KEY=ENV_KEY)
    cmd = [sys.executable, "-m", "swarmbox.run", *args]
    if not wait:
        return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)


def leaks(root: Path, *texts: str) -> list[str]:
    """Every file under ``root``, and each text, that holds one of the keys."""
    keys = [k.encode() for k in (CLI_KEY, ENV_KEY, SIGN_KEY, TYPO_KEY)]
    found = [str(p) for p in root.rglob("*") if p.is_file() and any(k in p.read_bytes() for k in keys)]
    return found + [t for t in texts if any(k.decode() in t for k in keys)]


def test_a_sweep_and_a_run_write_and_print_no_key(tmp_path):
    # one job flies, one is refused (its overrides reach sweep.json)
    sweep = swarmbox("-m", "algo=hover", "mission=hover", "network.loss_prob=0.0,1.5",
                     f"run.net.key={CLI_KEY}", f"hydra.sweep.dir={tmp_path / 'sweep'}",
                     "~hydra.callbacks.analyze")
    assert sweep.returncode == 2, sweep.stdout + sweep.stderr
    assert "run.net.key=***" in sweep.stdout + sweep.stderr   # the console job list, redacted
    assert "run.net.key=***" in (tmp_path / "sweep" / "multirun.yaml").read_text()
    summary = json.loads((tmp_path / "sweep" / "sweep.json").read_text())
    assert summary["counts"] == {"ok": 1} and "run.net.key=***" in summary["invalid"][0]["overrides"]
    run = swarmbox("algo=hover", "mission=hover", f"run.net.key={CLI_KEY}", "run.progress=false",
                   f"run.out_dir={tmp_path / 'run'}")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "run.net.key=***" in json.loads((tmp_path / "run" / "run.json").read_text())["overrides"]
    assert leaks(tmp_path, sweep.stdout, sweep.stderr, run.stdout, run.stderr) == []


def test_a_misspelt_or_misplaced_key_is_not_echoed_by_the_error(tmp_path):
    typo = swarmbox(f"run.net.kye={TYPO_KEY}", f"hydra.run.dir={tmp_path / 'a'}")
    misplaced = swarmbox(f"backend.signing_key={SIGN_KEY}", f"hydra.run.dir={tmp_path / 'b'}")  # sim: none
    for proc, name in ((typo, "run.net.kye"), (misplaced, "backend.signing_key")):
        assert proc.returncode == 2 and name in proc.stderr
        assert proc.stderr.count("\n") == 1
    assert leaks(tmp_path, typo.stderr, misplaced.stderr) == []


def _environ(pid: int) -> dict[str, str]:
    raw = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    return dict(e.decode(errors="replace").partition("=")[::2] for e in raw if e)


def _vehicle_pids(parents: list[int]) -> list[int]:
    """The mavsim vehicle processes the agents started (each names its agent's pid)."""
    out = []
    for proc in Path("/proc").iterdir():
        try:
            argv = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"swarmbox.hal.mavsim.process" in argv and b"--parent-pid" in argv:
            if int(argv[argv.index(b"--parent-pid") + 1]) in parents:
                out.append(int(proc.name))
    return out


def test_each_process_of_a_processes_run_gets_only_the_keys_it_needs(tmp_path):
    run_dir = tmp_path / "run"
    # a swarm key variable of the user's naming: it is still kept from the vehicles
    proc = swarmbox("run.runtime=processes", "backend=mavsim", f"backend.signing_key={SIGN_KEY}",
                    f"run.net.key={CLI_KEY}", "run.net.key_env=MY_SWARM_SECRET", "algo=hover",
                    "mission=hover", "algo.params.hover_s=1",
                    "run.progress=false", f"run.out_dir={run_dir}", wait=False)
    try:
        deadline = time.monotonic() + 300
        while not (run_dir / "nodes" / "start.json").exists():
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.1)
        pids = json.loads((run_dir / "nodes" / "pids.json").read_text())
        envs = {name: _environ(pid) for name, pid in pids.items()}
        vehicles = _vehicle_pids([pid for name, pid in pids.items() if name != "ground"])
        envs.update({f"vehicle_{k}": _environ(pid) for k, pid in enumerate(vehicles)})
        out, _ = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 0, out
    swarm, mavlink = "MY_SWARM_SECRET", "SWARMBOX_MAVLINK_KEY"
    assert envs["ground"].get(swarm) == CLI_KEY and mavlink not in envs["ground"]
    for i in range(4):
        assert envs[f"drone_{i}"].get(swarm) == CLI_KEY and envs[f"drone_{i}"].get(mavlink) == SIGN_KEY
    assert len(vehicles) == 4
    for k in range(4):
        assert swarm not in envs[f"vehicle_{k}"] and envs[f"vehicle_{k}"].get(mavlink) == SIGN_KEY
    assert not any(ENV_KEY in v for env in envs.values() for v in env.values())
    assert leaks(tmp_path, out) == []
