"""Typed algorithm params: every shipped algorithm declares them; bad ones stop the run before takeoff."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from hydra.utils import get_class

from swarmbox.run.params import ParamsError, typed_params
from tests.conftest import CONF, ROOT, compose_config

ALGOS = sorted(p.stem for p in (CONF / "algo").glob("*.yaml"))


@pytest.mark.parametrize("algo", ALGOS)
def test_every_shipped_algorithm_declares_params_and_its_yaml_matches_them(algo):
    cfg, _ = compose_config([f"algo={algo}"])
    schema = getattr(get_class(cfg.algo.drone._target_), "Params", None)
    assert schema is not None, f"{cfg.algo.drone._target_} declares no Params"
    params = typed_params(cfg.algo)
    assert set(params) == {f for f in schema.__dataclass_fields__}


def test_values_come_out_typed_and_errors_name_the_key():
    cfg, _ = compose_config(["algo=hover", "algo.params.hover_s=7"])
    assert typed_params(cfg.algo)["hover_s"] == 7.0 and isinstance(typed_params(cfg.algo)["hover_s"], float)
    cfg, _ = compose_config(["algo=hover", "algo.params.hover_s=abc"])
    with pytest.raises(ParamsError, match=r"algo\.params\.hover_s: .*'abc'.*HoverParams"):
        typed_params(cfg.algo)
    cfg, _ = compose_config(["algo=hover", "+algo.params.hover_ss=5"])
    with pytest.raises(ParamsError, match=r"algo\.params\.hover_ss: Key 'hover_ss' not in 'HoverParams'"):
        typed_params(cfg.algo)


@pytest.mark.parametrize("override, key", [("algo.params.hover_s=abc", "hover_s"),
                                           ("algo.params.hover_ss=5", "hover_ss"),
                                           ("+algo.params.hover_ss=5", "hover_ss")])
def test_a_bad_param_exits_non_zero_before_takeoff_naming_the_key(tmp_path, override, key):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "algo=hover", "mission=hover", override,
                           f"run.out_dir={out}"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert key in proc.stderr + proc.stdout
    run_json = Path(out / "run.json")
    if run_json.exists():   # the run was refused while being built: not one tick flown
        manifest = json.loads(run_json.read_text())
        assert manifest["status"] == "failed" and manifest["ticks"] == 0 and key in manifest["reason"]
        assert not list(out.glob("logs/drone_*/state.parquet"))
