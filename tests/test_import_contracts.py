"""The import contracts of pyproject.toml (docs/architecture.md) hold, and they do catch a breach.

Both run the real ``lint-imports`` command: once on the package as it is, then on copies of it into
which one forbidden import has been added.
"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# the `lint-imports` console script of this interpreter's environment
LINT = [str(Path(sys.executable).with_name("lint-imports")), "--no-cache", "--no-logo"]


def lint(root: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(root), "COLUMNS": "200"}
    return subprocess.run(LINT, cwd=root, env=env, capture_output=True, text=True, timeout=120)


def test_the_package_keeps_every_contract():
    proc = lint(ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 broken" in proc.stdout


# (module that gets the import, the import, the contract that must break, what the report says)
BREACHES = [
    ("core/agent.py", "import zenoh", "Only swarmbox.net talks Zenoh", "swarmbox.core.agent -> zenoh"),
    ("core/node.py", "import swarmbox.hal.vehicle", "Layers", "swarmbox.core.node -> swarmbox.hal.vehicle"),
    ("record/writer.py", "import swarmbox.run.config", "Layers",
     "swarmbox.record.writer -> swarmbox.run.config"),
    ("run/build.py", "import swarmbox.analysis.load", "Layers",
     "swarmbox.run.build -> swarmbox.analysis.load"),
    ("hal/sim/world.py", "import swarmbox.hal.px4.vehicle", "Backends",
     "swarmbox.hal.sim.world -> swarmbox.hal.px4.vehicle"),
    ("hal/sim/vehicle.py", "import swarmbox.hal.sim.backend", "SimFleet protocol",
     "swarmbox.hal.sim.vehicle -> swarmbox.hal.sim.backend"),
    ("algorithms/hover.py", "import swarmbox.core.stages", "Algorithms import only",
     "swarmbox.algorithms.hover -> swarmbox.core.stages"),
    ("core/ground.py", "import pymunk", "The core imports no", "swarmbox.core.ground -> pymunk"),
    ("net/medium.py", "import pandas", "The runtime never imports", "swarmbox.net.medium -> pandas"),
]


@pytest.mark.parametrize(("module", "statement", "contract", "chain"), BREACHES,
                         ids=[b[0] + ":" + b[1].split()[-1] for b in BREACHES])
def test_a_forbidden_import_breaks_its_contract(tmp_path, module, statement, contract, chain):
    shutil.copytree(ROOT / "swarmbox", tmp_path / "swarmbox", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    target = tmp_path / "swarmbox" / module
    target.write_text(target.read_text() + f"\n{statement}  # noqa: E402\n")
    proc = lint(tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert re.search(r"Contracts: \d+ kept, [1-9]\d* broken", proc.stdout), proc.stdout
    report = proc.stdout.split("Broken contracts", 1)[1]
    assert contract in report and f"{chain} (l." in report, proc.stdout
