"""Logic-environment isolation: the walls that import contracts cannot state.

The walls between SwarmBox's own packages, and the third-party libraries the core and the runtime
must not import, are import-linter contracts in pyproject.toml (tests/test_import_contracts.py).
Left here: the allow-list of third-party names for algorithms (a contract can only forbid), and
what the runtime actually loads (a lazy import by name would escape a static check).
"""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ALLOWED_IN_ALGORITHMS = {"swarmbox.api", "math", "numpy", "scipy", "typing", "collections", "dataclasses",
                         "itertools", "functools", "enum", "__future__", "heapq", "bisect", "random"}


def imports(path: Path) -> set[str]:
    mods = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            mods.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            mods.add(node.module)
    return mods


def test_algorithms_import_only_the_api_numpy_scipy_and_the_standard_library():
    for path in sorted((ROOT / "swarmbox" / "algorithms").rglob("*.py")):
        for mod in imports(path):
            if mod.startswith("swarmbox"):
                assert mod == "swarmbox.api", f"{path.name} imports {mod}"
            else:
                assert mod.split(".")[0] in {m.split(".")[0] for m in ALLOWED_IN_ALGORITHMS}, (path.name, mod)


def test_runtime_does_not_load_analysis_libraries():
    code = ("import sys, swarmbox.core.swarm, swarmbox.api, swarmbox.net.medium;"
            "bad = {'pandas', 'matplotlib', 'seaborn', 'pymunk', 'hydra', 'pymavlink'} & set(sys.modules);"
            "print(sorted(bad)); sys.exit(1 if bad else 0)")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_the_api_layer_depends_on_nothing_of_the_package_but_itself():
    """api < core: Stage and every user-visible type live in swarmbox.api; core builds on them."""
    for path in sorted((ROOT / "swarmbox" / "api").rglob("*.py")):
        for mod in imports(path):
            if mod.startswith("swarmbox"):   # the mission-area helper sits below the API
                assert mod.startswith(("swarmbox.api", "swarmbox.area")), f"{path.name} imports {mod}"
    from swarmbox.api import Stage
    from swarmbox.core.stages import Stage as CoreStage
    assert CoreStage is Stage


def test_no_context_exposes_ground_truth_or_wire_messages():
    from swarmbox.api import DroneContext, DroneState, GroundContext
    assert "true_pos_ned_m" not in DroneState._fields
    for ctx in (DroneContext, GroundContext):
        for name in dir(ctx):
            attr = getattr(ctx, name)
            if isinstance(attr, property):
                hint = str(attr.fget.__annotations__.get("return", ""))   # as written in the source
                for wire in ("Heartbeat", "TaskCommand", "core.messages", "Telemetry"):
                    assert wire not in hint, f"{ctx.__name__}.{name} returns {hint}"


def test_a_sim_run_loads_no_mavlink_and_the_analysis_commands_load_no_hydra():
    """What a process actually loads: a sim run's modules (build, checks, runner) without pymavlink,
    which only the MAVLink backends need; ``swarmbox detect`` and ``analyze`` without Hydra."""
    code = ("import sys, swarmbox.run.build, swarmbox.run.checks, swarmbox.run.runner,"
            " swarmbox.run.backend_schema;"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] == 'pymavlink'"
            " or m in ('swarmbox.hal.px4.backend', 'swarmbox.hal.mavsim.backend',"
            " 'swarmbox.hal.mavlink.codec'));"
            "print(bad); sys.exit(1 if bad else 0)")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for module in ("swarmbox.analysis.detection", "swarmbox.analysis.cli"):
        code = (f"import sys, {module};"
                "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('hydra', 'omegaconf'));"
                "print(bad); sys.exit(1 if bad else 0)")
        proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
        assert proc.returncode == 0, module + ": " + proc.stdout + proc.stderr
