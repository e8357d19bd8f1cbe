"""pyproject states, for every dependency and extra, the oldest release we accept and an upper bound
above the newest release tested (the next major), so a breaking release is opted into, not met."""

from __future__ import annotations

import tomllib

from packaging.requirements import Requirement

from tests.conftest import ROOT

PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def bounds(requirement: str) -> tuple[set[str], set[str]]:
    spec = Requirement(requirement).specifier
    return {s.operator for s in spec if s.operator in (">=", ">", "==", "~=")}, \
        {s.operator for s in spec if s.operator in ("<", "<=", "==", "~=")}


def test_every_dependency_has_a_lower_and_an_upper_bound():
    requirements = [*PROJECT["dependencies"],
                    *(r for extra in PROJECT["optional-dependencies"].values() for r in extra)]
    assert len(requirements) > 25
    unbounded = [r for r in requirements if not all(bounds(r))]
    assert unbounded == []
    assert not all(bounds("numpy>=1.26")) and not all(bounds("numpy<3"))   # the check itself


def test_the_test_extra_leaves_the_replay_libraries_out():
    names = {Requirement(r).name for r in PROJECT["optional-dependencies"]["test"]}
    replay = {Requirement(r).name for r in PROJECT["optional-dependencies"]["replay"]}
    assert "rerun-sdk" in replay and not names & (replay | {"swarmbox"})


def test_the_license_is_an_spdx_expression():
    assert PROJECT["license"] == "MIT"      # a table is deprecated by setuptools (removed 2027)
