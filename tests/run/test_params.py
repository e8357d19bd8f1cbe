"""Typed algorithm params: every shipped algorithm declares them; bad ones stop the run before takeoff."""

import subprocess
import sys

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
                                           ("algo.params.altitude_m=high", "altitude_m"),
                                           ("algo.params.hover_ss=5", "hover_ss"),
                                           ("+algo.params.hover_ss=5", "hover_ss")])
@pytest.mark.parametrize("runtime", ["single", "processes"])
def test_a_bad_param_is_refused_before_anything_is_written(tmp_path, override, key, runtime):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "algo=hover", "mission=hover", override,
                           f"run.runtime={runtime}", f"run.out_dir={out}"], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"algo.params.{key}" in lines[0], lines
    assert not out.exists()
