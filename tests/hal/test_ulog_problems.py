"""A ULog that cannot be collected is recorded in run.json ``problems``, not only printed."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from tests.hal.test_px4_sitl import FAKE_PX4, fake_ulog, ports_free

pytestmark = pytest.mark.slow   # four autopilot processes paced on the wall clock


def test_a_drone_without_a_ulog_is_a_problem_of_the_run(run, tmp_path, monkeypatch):
    if not ports_free([*range(14540, 14544), *range(14580, 14584)]):
        pytest.skip("PX4's SITL ports on 127.0.0.1 are in use on this machine")
    build = tmp_path / "build"
    (build / "bin").mkdir(parents=True)
    (build / "etc").mkdir()
    # instance 1's logger writes nothing
    fake = FAKE_PX4.replace('mkdir -p log/2025-01-01 && cp', '[ "$2" = 1 ] || mkdir -p log/2025-01-01 && cp')
    (build / "bin" / "px4").write_text(fake)
    (build / "bin" / "px4").chmod(0o755)
    fake_ulog(build / "fake.ulg", [(k * 200_000, 0.0, 0.0, -0.1 * k) for k in range(10)])
    monkeypatch.setenv("SWARMBOX_TEST_PYTHON", sys.executable)
    monkeypatch.setenv("PYTHONPATH", str(Path(__file__).resolve().parents[2]))
    manifest, d = run("algo=hover", "mission=hover", "algo.params.hover_s=1", "backend=px4",
                      f"backend.px4_build={build}", "backend.speed=2")
    assert manifest["status"] == "ok", manifest["reason"] or manifest["traceback"]
    missing = d / "px4" / "instance_1"
    assert manifest["problems"] == [f"drone 1: no ULog in {missing} (PX4's logger wrote none)"]
    assert [i for i in range(4) if (d / "logs" / f"drone_{i}" / "ulog.json").is_file()] == [0, 2, 3]
