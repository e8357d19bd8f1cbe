"""Mission input refused up front: spawns outside the geofence, positions of the wrong arity, absurd
coordinates, and ``mission.file`` paths that are not a readable regular file of sane size. Each one:
one line naming the cause, exit 2, nothing written."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from swarmbox.run.checks import check
from swarmbox.run.mission import MAX_MISSION_BYTES, MissionError, load
from tests.conftest import ROOT, compose_config

HOVER_AT = "mission.initial_positions={{0: [0, 0], 1: [5, 0], 2: [10, 0], 3: {last}}}"


def refused(tmp_path, *overrides: str) -> str:
    """Run the command line; assert exit 2, one line on stderr, no run directory. Returns the line."""
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "algo=hover", "mission=hover", *overrides,
                           f"run.out_dir={out}"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert not out.exists()
    return lines[0]


def test_a_spawn_far_away_or_outside_the_fence_is_refused_on_the_command_line(tmp_path):
    line = refused(tmp_path, HOVER_AT.format(last="[1e12, 0]"))
    assert "drone 3 starts 1e+12 m from the origin, outside the geofence" in line
    assert "run.safety.geofence_radius_m = 500 m" in line


@pytest.mark.parametrize("last, fence, why", [
    ("[15, 0, 4]", 500, "must be [north, east] (2 numbers), got 3"),
    ("[15]", 500, "must be [north, east] (2 numbers), got 1"),
    ("[15, 0]", 14.9, "drone 3 starts 15 m from the origin, outside the geofence"),
    ("[inf, 0]", 500, "must be finite"),
])
def test_bad_spawns_are_refused_naming_the_drone(last, fence, why):
    cfg, _ = compose_config(["algo=hover", "mission=hover", HOVER_AT.format(last=last),
                             f"run.safety.geofence_radius_m={fence}"])
    with pytest.raises(MissionError) as err:
        check(cfg)
    assert why in str(err.value) and "mission.initial_positions" in str(err.value)


def test_a_spawn_on_the_fence_is_accepted():
    cfg, _ = compose_config(["algo=hover", "mission=hover", "run.safety.geofence_radius_m=15"])
    assert load(cfg).initial_positions[3] == (15.0, 0.0, 0.0)


def test_a_mission_file_spawn_outside_the_fence_names_the_file(tmp_path):
    f = tmp_path / "far.yaml"
    f.write_text("drone_config:\n  initial_positions: {0: [0, 0], 1: [0, 900]}\n"
                 "mission_config: {type: far, swarm_size: 2}\n")
    cfg, _ = compose_config([f"mission.file={f}"])
    with pytest.raises(MissionError, match=rf"mission.file {f}.initial_positions: drone 1 starts 900 m"):
        load(cfg)


def _fifo(tmp_path):
    os.mkfifo(tmp_path / "pipe")
    return tmp_path / "pipe", "is a FIFO (named pipe), not a regular file"


def _loop(tmp_path):
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    return tmp_path / "loop", "is a symlink loop"


def _dangling(tmp_path):
    (tmp_path / "dangling").symlink_to(tmp_path / "gone.yaml")
    return tmp_path / "dangling", "is a symlink to a missing file"


def _directory(tmp_path):
    (tmp_path / "dir.yaml").mkdir()
    return tmp_path / "dir.yaml", "is a directory, not a regular file"


def _too_large(tmp_path):
    big = tmp_path / "big.yaml"
    with open(big, "wb") as fh:   # sparse: no disk used
        fh.truncate(MAX_MISSION_BYTES + 1)
    return big, f"is {MAX_MISSION_BYTES + 1} bytes (16 MiB), more than the 16 MiB allowed"


@pytest.mark.parametrize("make", [_fifo, _loop, _dangling, _directory, _too_large,
                                  lambda _: ("/dev/zero", "is a character device, not a regular file")],
                         ids=["fifo", "symlink_loop", "dangling_symlink", "directory", "too_large", "device"])
def test_a_mission_file_that_is_not_a_regular_file_is_named_for_what_it_is(tmp_path, make):
    path, why = make(tmp_path)
    cfg, _ = compose_config([f"mission.file={path}"])
    with pytest.raises(MissionError) as err:
        load(cfg)
    assert str(err.value).startswith(f"mission.file {path}: {why}"), str(err.value)


def test_a_fifo_mission_file_is_refused_on_the_command_line_without_blocking(tmp_path):
    path, why = _fifo(tmp_path)
    assert why in refused(tmp_path, f"mission.file={path}")
