"""Each node owns frozen views of params and mission; tasks go to direct inferiors only; markers
hold JSON values only. Whole runs through the hooks, in both runtimes where it matters."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT, table

HOVER = ("algo=hover", "mission=hover", "algo.params.hover_s=1")
TASKING = (*HOVER, "algo.drone._target_=tests.core.views_algos.PlainHover",
           "+algo.ground._target_=tests.core.views_algos.TaskingGround")
MARKING = (*HOVER, "algo.drone._target_=tests.core.views_algos.MarkingDrone")


def markers(d, node: str, name: str) -> list[dict]:
    ev = table(d, node, "events")
    return [json.loads(x) for x in ev[(ev["kind"] == "marker") & (ev["name"] == name)]["data"]]


@pytest.mark.parametrize("what", ["params", "mission"])
def test_a_hook_writing_a_shared_view_fails_the_run_naming_the_hook(run, what):
    manifest, d = run(*HOVER, "algo.drone._target_=tests.core.views_algos.WritingDrone",
                      f"+algo.params.write={what}")
    assert manifest["status"] == "failed"
    assert "drone 1: execution entry raised TypeError" in manifest["reason"], manifest["reason"]


def test_every_kind_of_write_is_refused_and_changes_nothing(run):
    manifest, d = run(*HOVER, "algo.drone._target_=tests.core.views_algos.TryWritingDrone",
                      "+algo.params.nested={k: [1, 2, 3]}")
    assert manifest["status"] == "ok", manifest["reason"]
    for i in range(4):
        [m] = markers(d, f"drone_{i}", "writes_refused")
        assert m == {"n": 7, "of": 7, "nested": {"k": [1, 2, 3]}, "hover_s": 1.0}


def test_in_the_processes_runtime_the_writer_fails_and_the_other_drones_see_the_original(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", *HOVER, "run.runtime=processes",
                           "algo.drone._target_=tests.core.views_algos.WritingDrone",
                           "+algo.params.write=params", f"run.out_dir={out}", "run.progress=false"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    manifest = json.loads((out / "run.json").read_text())
    writer = manifest["node_results"]["drone_1"]
    assert writer["status"] == "failed", proc.stdout + proc.stderr
    assert "drone 1: execution entry raised TypeError" in writer["reason"]
    for i in (0, 2, 3):
        [m] = markers(out, f"drone_{i}", "seen")
        assert m["hover_s"] == 1.0 and m["spawn_0"] == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("to, sent", [(1, True), (3, False), (2, False)])
def test_a_task_to_a_drone_that_is_not_a_direct_inferior_is_refused_and_counted(run, to, sent):
    # chain topology: ground -> 0 -> 1 -> 2 -> 3, so 0 is the ground's only inferior
    manifest, d = run(*TASKING, "topology=chain", f"+algo.params.to={0 if sent else to}")
    assert manifest["status"] == "ok", manifest["reason"]
    [m] = markers(d, "ground", "task_sent")
    assert m["sent"] is sent
    assert manifest["tasks_refused"] == ({} if sent else {"ground": 1})
    ev = table(d, "ground", "events")
    refused = ev[ev["name"] == "task_refused"]
    assert len(refused) == (0 if sent else 1)
    if not sent:
        assert refused["subject"].iloc[0] == to
        assert json.loads(refused["data"].iloc[0])["reason"] == "not a direct inferior"


@pytest.mark.parametrize("to", [999, -1])
def test_a_task_to_an_id_outside_the_mission_fails_the_hook(run, to):
    manifest, _ = run(*TASKING, f"+algo.params.to={to}")
    assert manifest["status"] == "failed"
    assert "ground: preparation entry raised ValueError" in manifest["reason"]
    assert f"send_task: {to} is not a drone of the mission" in manifest["reason"]


def test_markers_convert_numpy_values(run):
    manifest, d = run(*MARKING, "+algo.params.mark=numpy")
    assert manifest["status"] == "ok", manifest["reason"]
    [m] = markers(d, "drone_0", "values")
    assert m == {"f32": 1.5, "i64": 7, "arr": [0, 1, 2], "b": True, "grid": [[1.0, 0.0], [0.0, 1.0]],
                 "nested": {"x": [0.25, None]}}


def test_a_marker_holding_an_object_fails_naming_the_field(run):
    manifest, _ = run(*MARKING, "+algo.params.mark=object")
    assert manifest["status"] == "failed"
    assert ("execution entry raised TypeError: ctx.mark('values') field 'o' is a builtins.object, "
            "not a JSON value") in manifest["reason"]
