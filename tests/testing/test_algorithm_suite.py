"""The algorithm conformance suite: it rejects broken algorithms with a useful message and passes
every shipped one (on a small mission, under loss and jitter, twice)."""

import pytest

from swarmbox.testing import ConformanceError, check_algorithm
from tests.testing.shipped import SHIPPED, small

HOVER = ["algo=hover", "mission=hover", "algo.params.hover_s=1"]


@pytest.mark.slow
def test_hover_conforms_and_the_trace_shows_the_lifecycle(tmp_path):
    report = check_algorithm(HOVER, workdir=tmp_path)
    assert [m["status"] for m in report.manifests] == ["ok", "ok"]
    drone0 = [hook for node, hook, _ in report.traces[0].calls if node == "drone_0"]
    assert drone0.index("prep_once") < drone0.index("prep_loop") < drone0.index("exec_once") \
        < drone0.index("exec_loop")


@pytest.mark.parametrize("target, message", [
    ("UnseededDrone", "not deterministic: drone_"),
    ("TupleSetpointDrone", "exec_loop returned tuple"),
    ("NeverDoneDrone", "did not complete: aborted (EXECUTION timed out after 4 s"),
])
def test_broken_algorithms_fail_with_the_reason(tmp_path, target, message):
    with pytest.raises(ConformanceError, match="breaks the contract") as err:
        check_algorithm([*HOVER, f"algo.drone._target_=tests.testing.broken.{target}",
                         "run.timeouts_s.EXECUTION=4"], workdir=tmp_path)
    assert message in str(err.value), str(err.value)


def test_a_timeout_abort_passes_when_the_caller_accepts_aborts(tmp_path):
    report = check_algorithm([*HOVER, "algo.drone._target_=tests.testing.broken.NeverDoneDrone",
                              "run.timeouts_s.EXECUTION=4"], workdir=tmp_path, expect="any")
    assert all("timed out" in m["reason"] for m in report.manifests)


@pytest.mark.slow
@pytest.mark.parametrize("algo", sorted(SHIPPED))
def test_every_shipped_algorithm_conforms(tmp_path, algo):
    overrides, edit = small(algo)
    check_algorithm(overrides, workdir=tmp_path, edit=edit)


@pytest.mark.slow
def test_the_worked_example_of_the_docs_conforms(tmp_path):
    report = check_algorithm(["algo=hover", "mission=hover", "algo.name=shuttle",
                              "algo.drone._target_=tests.testing.shuttle.ShuttleDrone",
                              "+algo.ground._target_=tests.testing.shuttle.ShuttleGround",
                              "~algo.params.hover_s", "+algo.params.spacing_m=6"], workdir=tmp_path)
    assert [m["status"] for m in report.manifests] == ["ok", "ok"]


def _user_conf(root):
    """A user's own group entry: algo=mine, the shipped hover algorithm under another name."""
    (root / "conf" / "algo").mkdir(parents=True)
    (root / "conf" / "algo" / "mine.yaml").write_text(
        "defaults:\n  - hover\n  - _self_\nname: mine\nparams: {hover_s: 1}\n")


@pytest.mark.parametrize("relative", [True, False])
def test_a_user_config_dir_joins_the_shipped_groups(tmp_path, monkeypatch, relative):
    _user_conf(tmp_path)
    monkeypatch.chdir(tmp_path)
    config_dir = "conf" if relative else tmp_path / "conf"
    report = check_algorithm(["algo=mine", "mission=hover"], workdir=tmp_path / "runs", config_dir=config_dir)
    assert [(m["status"], m["choices"]["algo"], m["choices"]["mission"]) for m in report.manifests] == \
        [("ok", "mine", "hover")] * 2


def test_a_missing_config_dir_is_named_before_any_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="config_dir 'nope': no such directory"):
        check_algorithm(["algo=hover"], workdir=tmp_path / "runs", config_dir="nope")
    assert not (tmp_path / "runs").exists()
