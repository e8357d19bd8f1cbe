"""Only public APIs of our dependencies (STYLE §20): a private module (Hydra's internals, a plugin's
private core, joblib's vendored externals) changes without notice on a minor release, as joblib 1.6
did when it stopped vendoring cloudpickle.

Every ``import`` in the package, its Hydra plugins, the tests, the experiments and CI's Python is
read with ``ast``: a dependency's module path may not have a part starting with ``_``.
"""

from __future__ import annotations

import ast

from tests.conftest import ROOT

OURS = ("swarmbox", "tests", "hydra_plugins.swarmbox_launcher", "hydra_plugins.swarmbox_sweeper",
        "experiments")
# The names are spelt in parts so that a plain grep of the tree for private imports finds none.
INTERNAL, CORE, EXTERNALS = "_" + "internal", "_" + "core", "joblib." + "externals"
SOURCES = sorted(p for d in ("swarmbox", "hydra_plugins", "tests", "experiments", ".ci")
                 for p in (ROOT / d).rglob("*.py"))


def imported_modules(source: str) -> list[str]:
    """Every absolute module path ``source`` imports (``from a.b import c`` -> ``a.b`` and ``a.b.c``)."""
    modules = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules += [node.module, *(f"{node.module}.{alias.name}" for alias in node.names)]
    return modules


def private(module: str) -> bool:
    """A third-party module path with a private part (``hydra.<_private>.utils``)."""
    if module == "__future__" or module.startswith(OURS):
        return False
    return any(part.startswith("_") and not part.startswith("__") for part in module.split("."))


def test_the_check_sees_the_imports_that_broke_before():
    source = (f"from hydra.{INTERNAL}.core_plugins.basic_sweeper import BasicSweeper\n"
              f"import {EXTERNALS}.cloudpickle\n"
              f"from hydra_plugins.hydra_joblib_launcher.{CORE} import process_joblib_cfg\n"
              f"def f():\n    from {EXTERNALS} import loky\n")
    found = [m for m in imported_modules(source) if private(m) or m.startswith(EXTERNALS)]
    assert found == [f"hydra.{INTERNAL}.core_plugins.basic_sweeper",
                     f"hydra.{INTERNAL}.core_plugins.basic_sweeper.BasicSweeper",
                     f"{EXTERNALS}.cloudpickle", f"hydra_plugins.hydra_joblib_launcher.{CORE}",
                     f"hydra_plugins.hydra_joblib_launcher.{CORE}.process_joblib_cfg",
                     EXTERNALS, f"{EXTERNALS}.loky"]
    assert not private("swarmbox.run._helpers") and not private("hydra.core.utils")


def test_no_private_module_of_a_dependency_is_imported():
    assert len(SOURCES) > 200
    bad = {str(p.relative_to(ROOT)): found for p in SOURCES
           if (found := [m for m in imported_modules(p.read_text())
                         if private(m) or m.startswith(EXTERNALS)])}
    assert bad == {}


def test_no_plugin_of_hydra_is_imported_as_a_module():
    """Other Hydra plugins (``hydra_plugins.hydra_joblib_launcher``) are configs to select, not modules
    to import: their modules are theirs to change."""
    importers = [str(p.relative_to(ROOT)) for p in SOURCES
                 if any(m.startswith("hydra_plugins.") and not m.startswith(OURS)
                        for m in imported_modules(p.read_text()))]
    assert importers == []
