"""A full disk costs a run its tables, never its record: run.json is written (its space reserved
when the run starts) and names each table that could not be written; a table is on disk under its
final name only if it is complete (written as ``*.partial``, then renamed)."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

ROOT = Path(__file__).resolve().parents[2]
HOVER = ["algo=hover", "mission=hover", "run.progress=false"]


def swarmbox(run_dir: Path, preexec=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmbox.run", *HOVER, f"run.out_dir={run_dir}"],
                          capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                          preexec_fn=preexec, timeout=300)


def check_record(run_dir: Path, proc: subprocess.CompletedProcess, cause: str) -> list[str]:
    """run.json says which tables are missing and why; every table on disk is whole."""
    assert proc.returncode == 1, proc.stdout + proc.stderr
    manifest = json.loads((run_dir / "run.json").read_text())
    missing = manifest["tables_not_written"]
    assert manifest["status"] == "failed" and missing
    assert manifest["reason"] == f"could not finish logs: {', '.join(missing)} not written: {cause}"
    logs = run_dir / "logs"
    on_disk = sorted(p.relative_to(logs).as_posix() for p in logs.rglob("*.parquet"))
    assert on_disk and not set(missing) & set(on_disk)
    for name in on_disk:
        pq.read_table(run_dir / "logs" / name)   # complete: a cut file would not read
    assert sorted(p.name for p in run_dir.rglob("*") if p.is_file() and p.suffix != ".parquet") == [
        "config.yaml", "run.json"]   # no .partial file, no reservation left behind
    return missing


def test_a_file_size_limit_fails_the_run_naming_each_table(tmp_path):
    limit = 40 << 10   # the state tables (~55 kB each) do not fit, the rest does
    run_dir = tmp_path / "run"
    proc = swarmbox(run_dir, lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)))
    missing = check_record(run_dir, proc, "File too large")
    assert missing == [f"drone_{i}/state.parquet" for i in range(4)]


@pytest.fixture
def small_disk(tmp_path):
    """A 400 kB tmpfs (the run's tables need ~450 kB); skipped where mounting is not allowed."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=400k", "tmpfs", str(mnt)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


def test_a_full_disk_still_gets_run_json_naming_each_table(small_disk):
    run_dir = small_disk / "run"
    proc = swarmbox(run_dir)
    check_record(run_dir, proc, "No space left on device")
    assert proc.stderr.count("\n") <= 2   # the summary line and where the traceback is, no wall


def test_a_record_bigger_than_its_reservation_on_a_full_disk_is_written_without_its_bulk(small_disk,
                                                                                         monkeypatch):
    from swarmbox.run.record import RunJson

    monkeypatch.setattr(RunJson, "RESERVE", 4096)
    run_json = RunJson(small_disk, secrets={"s3cr3t-value"})
    run_json.reserve()
    filler = small_disk / "filler"
    with open(filler, "wb") as f, pytest.raises(OSError):   # the run's tables take the rest
        while True:
            f.write(b"\0" * 65536)
            f.flush()
    manifest = {"status": "failed", "reason": "key s3cr3t-value leaked?", "problems": [],
                "node_results": {f"drone_{i}": {"reason": "x" * 200} for i in range(100)}}
    run_json.write(manifest)
    written = json.loads((small_disk / "run.json").read_text())
    assert written["status"] == "failed" and written["reason"] == "key *** leaked?"
    assert "node_results" not in written
    assert written["problems"] == ["run.json shortened: No space left on device"]
    assert not (small_disk / ".run.json.tmp").exists()


def test_a_node_process_that_cannot_write_its_logs_says_so_in_run_json(tmp_path):
    """The processes runtime: each node writes its own tables; a node whose tables do not fit fails
    the run, and run.json names the node, the tables and the cause (each node's outcome has its space
    reserved before its logs, so it is never the thing that is lost)."""
    limit = 20 << 10   # each drone's state table (~23 kB here) and the ground's messages (~31 kB)
    run_dir = tmp_path / "run"
    env = {k: v for k, v in os.environ.items() if k != "SWARMBOX_NET_KEY"}
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", *HOVER, "run.runtime=processes",
                           "backend=mavsim", f"run.out_dir={run_dir}"], capture_output=True, text=True,
                          env=dict(env, PYTHONPATH=str(ROOT)), timeout=300,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)))
    assert proc.returncode == 1, proc.stdout + proc.stderr
    manifest = json.loads((run_dir / "run.json").read_text())
    assert manifest["status"] == "failed"
    missing = manifest["tables_not_written"]
    assert {f"drone_{i}/state.parquet" for i in range(4)} <= set(missing), missing
    for node in {t.split("/")[0] for t in missing}:
        outcome = manifest["node_results"][node]
        tables = [t for t in missing if t.startswith(f"{node}/")]
        assert outcome["status"] == "failed" and outcome["tables_not_written"] == tables
        assert f"{', '.join(tables)} not written: File too large" in manifest["reason"]
        assert node == "ground" or f"{node} failed" in manifest["reason"]
    for t in missing:
        assert not (run_dir / "logs" / t).exists()
    assert not list(run_dir.rglob("*.tmp")) and not list(run_dir.rglob("*.partial"))
