"""Resuming a sweep: finished runs are skipped, failed ones flown again with their record kept."""

import json

import pytest

from swarmbox.run.resume import ResumeMismatchError, finished_run


def write_run(run_dir, status, overrides):
    run_dir.mkdir(parents=True)
    (run_dir / "run.json").write_text(json.dumps({"status": status, "overrides": overrides}))
    (run_dir / "config.yaml").write_text("seed: 0\n")
    (run_dir / "logs").mkdir()


@pytest.mark.parametrize("status", ["ok", "aborted"])
def test_finished_run_is_skipped_and_left_untouched(tmp_path, status):
    write_run(tmp_path / "0", status, ["algo=hover", "seed=0"])
    before = (tmp_path / "0" / "run.json").read_bytes()
    manifest = finished_run(tmp_path / "0", ["seed=0", "algo=hover", "run.resume=true"])
    assert manifest["status"] == status
    assert (tmp_path / "0" / "run.json").read_bytes() == before


def test_failed_run_is_set_aside_and_flown_again(tmp_path):
    write_run(tmp_path / "0", "failed", ["seed=0"])
    assert finished_run(tmp_path / "0", ["seed=0"]) is None
    names = sorted(p.name for p in (tmp_path / "0").iterdir())
    assert names == ["config.failed-1.yaml", "logs.failed-1", "run.failed-1.json"]
    write_run(tmp_path / "1", "failed", ["seed=1"])
    (tmp_path / "1" / "run.failed-1.json").write_text("{}")          # an earlier attempt stays
    finished_run(tmp_path / "1", ["seed=1"])
    assert (tmp_path / "1" / "run.failed-2.json").is_file()
    assert (tmp_path / "1" / "run.failed-1.json").is_file()


def test_no_run_yet_means_fly(tmp_path):
    assert finished_run(tmp_path / "7", ["seed=7"]) is None


def test_a_finished_run_with_other_parameters_is_an_error(tmp_path):
    write_run(tmp_path / "0", "ok", ["algo=hover", "seed=0"])
    with pytest.raises(ResumeMismatchError, match="algo=formation"):
        finished_run(tmp_path / "0", ["algo=formation", "seed=0"])
