"""CI's jobs run in the virtual environments CI creates, never in whatever Python the machine has:
a job that installs into or tests with the machine's ``python3`` proves nothing about a fresh
install (the joblib 1.6 break passed a CI that reused its environment)."""

from __future__ import annotations

import re

from tests.conftest import ROOT

SCRIPTS = [*sorted((ROOT / ".ci").glob("*.sh")), ROOT / ".ci" / "run",
           ROOT / "experiments" / "rq4_delivery" / "ci.sh"]
# The machine's interpreter may create a venv (python3 -m venv) or run a stdlib-only helper script;
# installing, testing or running SwarmBox with it is what this refuses.
MACHINE_PYTHON = re.compile(r"(?<![\w$/.-])(python3?|pip3?)\s+(-m\s+(pip|pytest|swarmbox\S*)|install)\b")


def machine_python_lines(text: str) -> list[str]:
    return [ln.strip() for ln in text.splitlines()
            if not ln.lstrip().startswith("#") and MACHINE_PYTHON.search(ln.split(" #")[0])]


def test_the_check_sees_a_job_using_the_machines_python():
    main_ci = ("python3 -m pip install --quiet -e '.[test,ray,slurm]'\npython3 -m pytest\n"
               "pip install -e .\npython -m swarmbox.run -m x\n")
    assert len(machine_python_lines(main_ci)) == 4
    ours = ('"$PYTHON" -m pytest\n"$work/extras/bin/pip" install -e .\npython3 -m venv "$1"\n'
            'python3 "$ci/readme_commands.py" README.md\n"$venv/bin/python" -m pytest\n')
    assert machine_python_lines(ours) == []


def test_no_ci_job_installs_or_tests_with_the_machines_python():
    assert len(SCRIPTS) >= 8
    found = {str(p.relative_to(ROOT)): lines for p in SCRIPTS
             if (lines := machine_python_lines(p.read_text()))}
    assert found == {}
