"""Config groups offer only real choices, and every shipped preset composes as it always did.

Schemas and shared bases (``backend/*_schema``, ``algo/delivery_base``, ``experiment/rq3_common``)
are building blocks, not options: they live outside the selectable groups. Moving them must not
change any composed config, which ``data/composed_presets.json`` pins: one digest per preset and
config section, taken before the move. A change to a preset that is meant rewrites the file::

    python -m tests.run.test_config_groups --write
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from swarmbox.run.config import register
from tests.conftest import CONF, ROOT

SNAPSHOT = Path(__file__).parent / "data" / "composed_presets.json"
PRESET_GROUPS = ("algo", "mission", "backend", "experiment")
INTERNAL = ("backend=sim_schema", "backend=px4_schema", "backend=mavsim_schema", "algo=delivery_base",
            "+experiment=rq3_common")


def presets() -> list[str]:
    """Every shipped preset as the override that selects it."""
    out = []
    for group in PRESET_GROUPS:
        for path in sorted((CONF / group).glob("*.yaml")):
            out.append(f"+experiment={path.stem}" if group == "experiment" else f"{group}={path.stem}")
    return out


def _compose(override: str) -> dict:
    register()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", overrides=[override], return_hydra_config=True)
    GlobalHydra.instance().clear()
    job = OmegaConf.to_container(cfg, resolve=False)
    job.pop("hydra")
    sections = dict(job)
    # the parts of Hydra's own config a preset sets (launcher, sweep parameters, callbacks)
    for key in ("launcher", "sweeper", "callbacks"):
        sections[f"hydra.{key}"] = OmegaConf.to_container(cfg.hydra[key], resolve=False)
    sections["hydra.sweep.dir"] = OmegaConf.to_container(cfg.hydra.sweep, resolve=False)["dir"]
    return sections


def digests(override: str) -> dict[str, str]:
    """One digest per config section of the composed preset (key order kept: it is part of the config)."""
    return {key: hashlib.sha256(json.dumps(value).encode()).hexdigest()[:16]
            for key, value in sorted(_compose(override).items())}


@pytest.mark.parametrize("override", presets())
def test_every_preset_composes_as_before(override):
    pinned = json.loads(SNAPSHOT.read_text())
    assert override in pinned, f"{override} is not pinned: python -m tests.run.test_config_groups --write"
    now = digests(override)
    changed = sorted(k for k in set(now) | set(pinned[override]) if now.get(k) != pinned[override].get(k))
    assert not changed, f"{override}: sections {changed} compose differently"


def test_every_pinned_preset_still_exists():
    assert sorted(json.loads(SNAPSHOT.read_text())) == sorted(presets())


@pytest.mark.parametrize("override", INTERNAL)
def test_internal_entries_are_not_selectable(override):
    register()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        with pytest.raises(ConfigCompositionException, match="Could not find"):
            compose("config", overrides=[override])
    GlobalHydra.instance().clear()


def test_schema_as_backend_is_refused_on_the_command_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "swarmbox.run", "backend=sim_schema",
                           f"run.out_dir={tmp_path / 'r'}"], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    assert "sim_schema" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()


def _write() -> None:
    SNAPSHOT.parent.mkdir(exist_ok=True)
    SNAPSHOT.write_text(json.dumps({o: digests(o) for o in presets()}, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python -m tests.run.test_config_groups --write")
    _write()
