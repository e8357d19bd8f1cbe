"""Every command block of the README, in short versions: it composes (fast) and it runs (slow).

Short versions: sweeps of 2 seeds instead of 20, MAVLink vehicles paced for the machine, outputs
in a temporary directory. PX4 SITL is not on this machine, so the PX4 lines are composed, and
``backend=px4`` with no vehicle is checked to report while it waits and to fail clearly.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser

from swarmbox.run.sweeper import sweep_jobs
from tests import realtime
from tests.conftest import ROOT, compose_config

README = (ROOT / "README.md").read_text()


def commands() -> list[list[str]]:
    """Each ``python -m swarmbox.*`` command of the README's bash blocks, as argv (comments dropped)."""
    out = []
    for block in re.findall(r"```bash\n(.*?)```", README, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            argv = shlex.split(line, comments=True)
            for part in " ".join(argv).split(" && "):
                words = shlex.split(part)
                if words[:2] == ["python", "-m"] and words[2].startswith("swarmbox."):
                    out.append(words[2:])
    return out


RUNS = [c[1:] for c in commands() if c[0] == "swarmbox.run"]


def shorten(args: list[str]) -> list[str]:
    args = [re.sub(r"range\(20\)", "range(2)", a) for a in args]
    return [a.replace("$HOME", str(Path.home())) for a in args]


def test_the_readme_has_the_commands_it_should():
    names = [c[0] for c in commands()]
    assert names.count("swarmbox.run") >= 12 and "swarmbox.analyze" in names and "swarmbox.compare" in names


def jobs(args: list[str]) -> list[list[str]]:
    """The override lists of the jobs a command makes (a sweep: every combination)."""
    overrides = [a for a in args if a != "-m" and not a.startswith(("hydra/launcher", "hydra."))]
    if "-m" not in args:
        return [overrides]
    parsed = OverridesParser.create().parse_overrides(overrides)
    return sweep_jobs(parsed, None)[0]


@pytest.mark.parametrize("args", RUNS, ids=" ".join)
def test_every_readme_run_composes(args):
    for overrides in jobs(shorten(args)):
        compose_config(overrides)    # raises on a misspelt key, a bad value or an unknown choice


def swarmbox(module: str, args: list[str], cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", module, *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.slow
def test_every_readme_command_runs(tmp_path):
    (tmp_path / "experiments").symlink_to(ROOT / "experiments")        # mission files, relative paths
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "baselines").symlink_to(ROOT / "results" / "baselines")
    speed = f"run.speed={realtime.speed(4.0)}"
    for args in RUNS:
        args = shorten(args)
        if "backend=px4" in args:
            if any(a.startswith("backend.px4_build=") for a in args):
                continue                    # needs a PX4 build; composed by the test above
            free = ",".join(["'udpin:127.0.0.1:0'"] * 4)     # no vehicle there; never a busy port
            args = [*args, "backend.connect_timeout_s=6", f"backend.connections=[{free}]",
                    f"run.out_dir={tmp_path / 'px4'}"]
            proc = swarmbox("swarmbox.run", args, tmp_path)
            out = proc.stderr + proc.stdout
            assert proc.returncode != 0 and "not heard (HEARTBEAT" in out, out[-2000:]
            assert "0/4 vehicles heard" in out                 # progress while it waits
            continue
        if "backend=mavsim" in args:          # a shorter formation, paced for the machine
            args = [a if not a.startswith("run.speed=") else speed for a in args]
            args += ["algo.params.start_s=2", "algo.params.angular_rate_rad_s=0.6",
                     "algo.params.complete_after_s=8"]
        proc = swarmbox("swarmbox.run", args, tmp_path)
        assert proc.returncode == 0, f"{args}\n{proc.stderr[-3000:]}"
    runs = sorted((tmp_path / "results" / "runs").glob("*/run.json"))
    sweeps = sorted(p for p in (tmp_path / "results" / "sweeps").iterdir() if (p / "tables").is_dir())
    assert runs and sweeps
    manifests = [json.loads(p.read_text()) for p in runs]
    file_run = [m for m in manifests if any(o.startswith("mission.file=") for o in m["overrides"])]
    assert file_run and file_run[0]["choices"]["mission"] == "rq2_sim2real"       # the file's own name
    for name, *args in commands():
        if name == "swarmbox.run":
            continue
        args = [a.replace("results/runs/<run>", str(runs[0].parent))
                 .replace("results/sweeps/<sweep>", str(sweeps[0])) for a in args]
        proc = swarmbox(name, args, tmp_path)
        assert proc.returncode in (0, 1), f"{name} {args}\n{proc.stderr[-3000:]}"   # compare: 1 = regression
    # The tour's algorithm (a module and a YAML, run from its own folder) and the pandas example.
    for path, body in re.findall(r"```(?:python|yaml)\n# (\S+)\n(.*?)```", README, flags=re.S):
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(body)
    (tmp_path / "my_lab" / "__init__.py").write_text("")
    proc = swarmbox("swarmbox.cli", ["run", "--config-dir", "conf", "algo=my_hover", "mission=hover",
                                     f"run.out_dir={tmp_path / 'mine'}"], tmp_path)
    assert proc.returncode == 0 and json.loads((tmp_path / "mine" / "run.json").read_text())["status"] == "ok"
    example = re.search(r"```python\n(import swarmbox\n.*?)```", README, flags=re.S).group(1)
    proc = swarmbox("swarmbox.cli", ["--help"], tmp_path)      # the console command's own help
    assert proc.returncode == 0 and "analyze" in proc.stdout
    code = example.replace("results/sweeps/<sweep>", str(sweeps[0]))
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]


# CI runs the "Two commands" block as written (.ci/readme.sh): the extraction is checked here.

def readme_commands(readme: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / ".ci" / "readme_commands.py"), str(readme)],
                          capture_output=True, text=True, timeout=60)


def test_ci_extracts_exactly_the_two_commands_of_the_readme_verbatim():
    proc = readme_commands(ROOT / "README.md")
    assert proc.returncode == 0, proc.stderr
    install, test = proc.stdout.splitlines()
    assert install.startswith("pip install -e '.[test]' && python -m swarmbox.run")
    assert test.split("#")[0].split() == ["python", "-m", "pytest", "-n", "auto"]   # one worker per core
    section = README.split("## Two commands", 1)[1].split("\n## ", 1)[0]
    assert f"\n{install}\n" in section and f"\n{test}\n" in section      # whole lines, unchanged


@pytest.mark.parametrize("text, cause", [
    ("# SwarmBox\n\n## Install\n\n```bash\npip install swarmbox\npytest\n```\n",
     "no '## Two commands' section"),
    ("## Two commands\n\nSee below.\n\n## Tour\n\n```bash\npip install .\npytest\n```\n", "no ```bash block"),
    ("## Two commands\n\n```bash\npip install .\n# a comment\n```\n", "1 commands"),
    ("## Two commands\n\n```bash\npip install .\npython -m pytest\nmake\n```\n", "3 commands"),
])
def test_ci_refuses_a_readme_without_its_two_commands(tmp_path, text, cause):
    (tmp_path / "README.md").write_text(text)
    proc = readme_commands(tmp_path / "README.md")
    assert proc.returncode == 2 and cause in proc.stderr and not proc.stdout
    job = subprocess.run(["bash", str(ROOT / ".ci" / "readme.sh"), str(tmp_path), str(tmp_path / "venv")],
                         capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert job.returncode == 2 and cause in job.stderr
    assert not (tmp_path / "venv").exists()                  # refused before any install
