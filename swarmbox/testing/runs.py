"""Running configs for the conformance suites: compose like the CLI, fly, read the logs back."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
from hydra import compose as hydra_compose
from hydra import initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig, OmegaConf, open_dict

from swarmbox.run.config import register
from swarmbox.run.runner import execute, run_choices

PACKAGED_CONF = Path(__file__).resolve().parents[1] / "conf"


def search_path_override(config_dir: str | Path) -> str:
    """``hydra.searchpath`` adding ``config_dir`` (relative: to the current directory) beside the
    shipped groups, as ``swarmbox run --config-dir DIR`` does; a missing directory raises."""
    path = Path(config_dir).expanduser().resolve()
    if not path.is_dir():
        raise FileNotFoundError(f"config_dir {str(config_dir)!r}: no such directory ({path})")
    quoted = str(path).replace("\\", "\\\\").replace("'", "\\'")
    return f"hydra.searchpath=['file://{quoted}']"


def compose(overrides: Sequence[str],
            config_dir: str | Path | None = None) -> tuple[DictConfig, dict[str, str]]:
    """The config ``python -m swarmbox.run [--config-dir DIR] OVERRIDES`` would run, and its group choices."""
    register()
    extra = [search_path_override(config_dir)] if config_dir is not None else []
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(PACKAGED_CONF), version_base="1.3"):
        cfg = hydra_compose("config", overrides=[*overrides, *extra], return_hydra_config=True)
    choices = run_choices(cfg, OmegaConf.to_container(cfg.hydra.runtime.choices))
    with open_dict(cfg):
        del cfg["hydra"]
    GlobalHydra.instance().clear()
    return cfg, choices


def fly(cfg: DictConfig, choices: dict[str, str], run_dir: Path,
        prepare: Callable[[Any], None] | None = None) -> dict[str, Any]:
    return execute(cfg, Path(run_dir), choices, [], prepare)


def _tables(run_dir: Path) -> dict[str, Path]:
    logs = Path(run_dir) / "logs"
    return {str(p.relative_to(logs)): p for p in sorted(logs.rglob("*.parquet"))}


def last_states(run_dir: Path) -> dict[str, tuple[bool, bool]]:
    """(armed, landed) in each drone's last state row."""
    out = {}
    for rel, path in _tables(run_dir).items():
        node, table = rel.split("/")[0], Path(rel).stem
        if table == "state":
            t = pq.read_table(path, columns=["armed", "landed"])
            if t.num_rows:
                out[node] = (bool(t["armed"][-1].as_py()), bool(t["landed"][-1].as_py()))
    return out


def compare_logs(a: Path, b: Path) -> list[str]:
    """Differences between two runs' logs: missing tables, then the first differing row of each."""
    ta, tb = _tables(a), _tables(b)
    out = [f"{rel} written by one run only" for rel in sorted(set(ta) ^ set(tb))]
    for rel in sorted(set(ta) & set(tb)):
        x, y = pq.read_table(ta[rel]), pq.read_table(tb[rel])
        if x.equals(y):
            continue
        if x.num_rows != y.num_rows:
            out.append(f"{rel}: {x.num_rows} rows vs {y.num_rows}")
            continue
        for col in x.column_names:
            cx, cy = x[col].to_pylist(), y[col].to_pylist()
            diff = next((i for i, (p, q) in enumerate(zip(cx, cy, strict=True))
                         if p != q and not (p != p and q != q)), None)   # NaN == NaN here
            if diff is not None:
                out.append(f"{rel}: column {col} first differs at row {diff} ({cx[diff]!r} vs {cy[diff]!r})")
                break
    return out
