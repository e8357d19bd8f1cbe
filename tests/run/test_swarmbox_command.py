"""The ``swarmbox`` console command as a user types it: the installed script in real subprocesses."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from swarmbox.cli import COMMANDS
from tests.conftest import ROOT

SCRIPT = Path(sys.executable).parent / "swarmbox"
COMMAND = [str(SCRIPT)] if SCRIPT.is_file() else [sys.executable, "-m", "swarmbox.cli"]
HOVER = ["algo=hover", "mission=hover", "algo.params.hover_s=1"]


def swarmbox(*args, cwd=ROOT, timeout=300):
    return subprocess.run([*COMMAND, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def test_help_lists_every_subcommand_on_one_line_each():
    proc = swarmbox("--help")
    assert proc.returncode == 0
    rows = [line.split()[0] for line in proc.stdout.splitlines() if line.startswith("  ")]
    assert rows == ["run", "analyze", "compare", "export", "detect", "bench", "check"] == list(COMMANDS)


@pytest.mark.parametrize("command", [c for c in COMMANDS if c != "run"])
def test_every_subcommand_has_its_own_help(command):
    proc = swarmbox(command, "--help", timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage:") and "--help" in proc.stdout


def test_run_help_opens_with_swarmbox_and_lists_only_real_choices():
    proc = swarmbox("run", "--help", timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("swarmbox run: fly a mission")
    assert "powered by Hydra" not in proc.stdout and "__main__" not in proc.stdout
    groups = dict(line.split(": ", 1) for line in proc.stdout.splitlines()
                  if line.split(":")[0] in ("algo", "mission", "backend", "topology", "network", "fault",
                                            "experiment"))
    assert len(groups) == 7
    assert groups["backend"].split(", ") == ["mavsim", "px4", "sim", "sim_px4"]
    assert "delivery_distance_dynamic" in groups["algo"] and "delivery_base" not in groups["algo"]
    assert "rq3_loss" in groups["experiment"] and "rq3_common" not in groups["experiment"]
    assert "_schema" not in proc.stdout


def test_unknown_subcommand_is_one_line_and_exit_2():
    proc = swarmbox("exprt", "results")
    assert proc.returncode == 2 and proc.stdout == ""
    assert len(proc.stderr.strip().splitlines()) == 1 and "'exprt'" in proc.stderr


def test_no_subcommand_is_a_usage_error():
    proc = swarmbox()
    assert proc.returncode == 2 and "usage: swarmbox" in proc.stderr


@pytest.mark.parametrize("command, never", [
    ("run", ["pandas", "matplotlib", "swarmbox.analysis"]),
    ("analyze", ["pymunk", "swarmbox.run.runner", "swarmbox.hal.sim"]),
    ("compare", ["pymunk", "swarmbox.run.runner", "swarmbox.hal.sim"]),
    ("export", ["pymunk", "swarmbox.run.runner", "hydra", "matplotlib"]),
    ("detect", ["pymunk", "swarmbox.run.runner", "swarmbox.hal.sim"]),
    ("bench", ["pandas", "hydra", "numpy"]),
    ("check", ["pandas", "hydra", "numpy"]),
])
def test_each_subcommand_imports_only_what_it_needs(command, never):
    code = ("import sys\nfrom swarmbox import cli\nnames = sys.argv[2:]\ntry:\n"
            "    cli.main([sys.argv[1], '--help'])\nexcept SystemExit:\n    pass\n"
            "print('LOADED', ' '.join(m for m in names if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code, command, *never], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    loaded = proc.stdout.strip().splitlines()[-1]
    assert loaded == "LOADED", f"swarmbox {command} --help loaded {loaded.split()[1:]}"


@pytest.mark.replay
def test_export_writes_a_replay_of_a_run(tmp_path):
    pytest.importorskip("foxglove_schemas_protobuf", reason="needs the replay extra")
    run = tmp_path / "r"
    assert swarmbox("run", *HOVER, f"run.out_dir={run}").returncode == 0
    proc = swarmbox("export", str(run), "--format", "mcap")
    assert proc.returncode == 0, proc.stderr
    mcap = run / "replay" / "run.mcap"
    assert mcap.read_bytes()[:8] == b"\x89MCAP0\r\n" and f"mcap: {mcap}" in proc.stdout
    again = swarmbox("export", str(run), "--format", "mcap")   # never overwritten unasked
    assert again.returncode == 2 and "already exists" in again.stderr


def test_run_refuses_bad_input_in_one_line_as_python_m_does(tmp_path):
    proc = swarmbox("run", "run.tick_hzz=20", f"run.out_dir={tmp_path / 'x'}")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "tick_hzz" in proc.stderr
    assert not (tmp_path / "x").exists()


def test_check_passes_a_conforming_algorithm_and_fails_a_broken_one(tmp_path):
    ok = swarmbox("check", HOVER[0], "--workdir", str(tmp_path / "ok"), *HOVER[1:])   # options anywhere
    assert ok.returncode == 0, ok.stderr[-2000:]
    assert ok.stdout.startswith("PASS  algorithm 'hover'")
    assert [json.loads((tmp_path / "ok" / r / "run.json").read_text())["status"]
            for r in ("first", "second")] == ["ok", "ok"]
    bad = swarmbox("check", *HOVER, "algo.drone._target_=tests.testing.broken.TupleSetpointDrone")
    assert bad.returncode == 1 and "FAIL" in bad.stderr and "exec_loop returned tuple" in bad.stderr
    unknown = swarmbox("check", "algo=nope")
    assert unknown.returncode == 2 and len(unknown.stderr.strip().splitlines()) == 1
    assert "nope" in unknown.stderr
