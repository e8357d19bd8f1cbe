"""The batch API example of docs/algorithms.md, verbatim: a user's project whose per-drone algorithm
and batch port pass ``check_batch_matches`` with one pytest command."""

import os
import re
import subprocess
import sys
from pathlib import Path

from tests.conftest import ROOT

DOC = ROOT / "docs" / "algorithms.md"
FILES = {"my_lab/climb.py", "conf/algo/climb.yaml", "conf/algo/climb_batch.yaml", "tests/test_climb.py"}


def write_project(root: Path) -> None:
    section = DOC.read_text().split("## The whole fleet at once")[1].split("\n## ")[0]
    blocks = re.findall(r"```(?:python|yaml)\n# (\S+)\n(.*?)```", section, flags=re.S)
    assert {path for path, _ in blocks} == FILES
    for path, body in blocks:
        (root / path).parent.mkdir(parents=True, exist_ok=True)
        (root / path).write_text(body)
    (root / "my_lab" / "__init__.py").write_text("")


def _pytest(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"], cwd=root,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                          timeout=600)


def test_documented_batch_port_writes_the_per_drone_logs(tmp_path):
    write_project(tmp_path)
    proc = _pytest(tmp_path)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "1 passed" in proc.stdout


def test_documented_check_fails_when_the_port_drifts(tmp_path):
    write_project(tmp_path)
    code = tmp_path / "my_lab" / "climb.py"
    code.write_text(code.read_text().replace("target[:, 2] = -4.0", "target[:, 2] = -4.01"))
    proc = _pytest(tmp_path)
    assert proc.returncode == 1
    assert "BatchMismatch" in proc.stdout and "setpoints.parquet" in proc.stdout
