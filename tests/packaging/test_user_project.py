"""A user's own project (docs/user-projects.md, verbatim) runs against SwarmBox with one command."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from tests.conftest import ROOT

DOC = ROOT / "docs" / "user-projects.md"


def write_project(root: Path) -> None:
    """Write every code block of the docs page that starts with a ``# <path>`` comment."""
    blocks = re.findall(r"```(?:python|yaml)\n# (\S+)\n(.*?)```", DOC.read_text(), flags=re.S)
    assert {path for path, _ in blocks} == {"my_lab/flock.py", "conf/algo/flock.yaml", "tests/test_flock.py"}
    for path, body in blocks:
        (root / path).parent.mkdir(parents=True, exist_ok=True)
        (root / path).write_text(body)
    (root / "my_lab" / "__init__.py").write_text("")


def test_documented_user_project_flies_with_one_command(tmp_path):
    write_project(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}   # SwarmBox itself, as if installed; not the project
    proc = subprocess.run([sys.executable, "-m", "swarmbox.cli", "run", "--config-dir", "conf", "algo=flock",
                           "run.out_dir=out"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    manifest = json.loads((tmp_path / "out" / "run.json").read_text())
    assert manifest["status"] == "ok", manifest["reason"]
    assert manifest["choices"]["algo"] == "flock" and manifest["choices"]["mission"] == "hover"
    import pandas as pd

    events = pd.read_parquet(tmp_path / "out" / "logs" / "drone_0" / "events.parquet")
    assert "arrived" in set(events["name"])     # the user's own marker, from the user's own code


def test_unknown_user_algorithm_names_the_group_and_choice(tmp_path):
    write_project(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "swarmbox.cli", "run", "--config-dir", "conf", "algo=flok"],
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode != 0
    assert "flok" in proc.stderr and "flock" in proc.stderr   # Hydra lists the available choices


def test_documented_pytest_example_runs_the_conformance_suite_on_the_project(tmp_path):
    write_project(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "1 passed" in proc.stdout


def test_documented_pytest_example_fails_when_the_algorithm_breaks_the_contract(tmp_path):
    write_project(tmp_path)
    flock = tmp_path / "my_lab" / "flock.py"   # a tuple where a Setpoint belongs
    source = flock.read_text().replace("return Setpoint.position(*self.target)", "return self.target")
    flock.write_text(source)
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"],
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 1, proc.stdout[-3000:]
    assert "ConformanceError: algorithm 'flock' breaks the contract" in proc.stdout
