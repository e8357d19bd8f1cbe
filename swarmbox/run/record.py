"""The run record, the same for both runtimes: what ``run.json`` holds and how it reaches the disk.

Both runtimes (one process, or one process per node) build their manifest with :func:`new_manifest`,
decide status and reason by the rules here, hide every secret with one code path (:func:`scrub`,
:func:`public_config`, :func:`redact_overrides`) and write the record with :class:`RunJson`, whose
file is reserved on disk before the run writes anything else — so a full disk costs the run its
tables, never its record. ``run.json`` is written last: it marks the run finished.
"""

from __future__ import annotations

import json
import logging
import os
import platform
import subprocess
from collections.abc import Iterable, Mapping
from datetime import UTC, datetime
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from swarmbox import __version__
from swarmbox.core.messages import GROUND_ID
from swarmbox.core.rows import TEXTS
from swarmbox.hal.launch import KEY_VARS
from swarmbox.record.schema import SCHEMA_VERSION, node_name

_PROJECT_ROOT = Path(__file__).resolve().parents[2]
MASK = "***"
#: Environment variables that carry keys; a child process gets only those it needs.
KEY_ENVS = frozenset({"SWARMBOX_NET_KEY", "SWARMBOX_MAVLINK_KEY"})


class RunExistsError(FileExistsError):
    """The run directory already holds a finished run (or another process is writing into it)."""


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename: all of it, or nothing."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)


# -- versions ------------------------------------------------------------------------------------
def versions() -> dict[str, str]:
    return dict(_package_versions())


@cache
def _package_versions() -> tuple[tuple[str, str], ...]:
    """What this process runs on (read once: a sweep worker runs many jobs)."""
    out = {"swarmbox": __version__, "python": platform.python_version()}
    for pkg in ("numpy", "pymunk", "hydra-core", "omegaconf", "pyarrow", "pymavlink"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return tuple(out.items())


@cache
def git_sha() -> str | None:
    """The checkout's commit when this process first asks: the code it imported (a sweep worker
    would otherwise start a ``git`` process per job)."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=_PROJECT_ROOT, capture_output=True,
                             text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None


# -- secrets -------------------------------------------------------------------------------------
def is_secret(name: str) -> bool:
    """A config key whose value is a secret: ``key`` or any ``*_key`` (``run.net.key``,
    ``backend.signing_key``), whatever its path; ``+``/``~`` prefixes ignored."""
    leaf = name.lstrip("+~").rsplit(".", 1)[-1].lower()
    return leaf == "key" or leaf.endswith("_key")


def redact_overrides(overrides: Iterable[str]) -> list[str]:
    """Command-line overrides with the value of every secret hidden (``run.net.key=***``)."""
    out = []
    for o in overrides:
        name, eq, value = o.partition("=")
        out.append(f"{name}={MASK}" if eq and value and is_secret(name) else o)
    return out


def secret_values(cfg: DictConfig | None = None, overrides: Iterable[str] = (),
                  env: Mapping[str, str] | None = None) -> set[str]:
    """Every secret value this run knows of: in its overrides (even misspelt or misplaced ones), its
    config and the key variables of the environment. Empty values are not secrets."""
    found = {o.partition("=")[2] for o in overrides if is_secret(o.partition("=")[0])}
    names = set(KEY_ENVS)
    if cfg is not None:
        found.update(str(v) for v in _secret_leaves(OmegaConf.to_container(cfg, resolve=False)))
        names.add(str(OmegaConf.select(cfg, "run.net.key_env", default="") or ""))
    env = os.environ if env is None else env
    found.update(env[n] for n in names if n and env.get(n))
    return {v.strip("'\"") for v in found if v and v.strip("'\"") and v not in ("None", "null")}


def _secret_leaves(node: Any) -> Iterable[Any]:
    if isinstance(node, dict):
        for k, v in node.items():
            if is_secret(str(k)) and v not in (None, ""):
                yield v
            else:
                yield from _secret_leaves(v)
    elif isinstance(node, list):
        for v in node:
            yield from _secret_leaves(v)


def scrub(value: Any, secrets: Iterable[str]) -> Any:
    """``value`` (text, or lists and dicts of it) with every secret replaced by ``***``."""
    keys = sorted((s for s in secrets if s), key=len, reverse=True)
    if not keys:
        return value
    return _scrub(value, keys)


def _scrub(value: Any, keys: list[str]) -> Any:
    if isinstance(value, str):
        for k in keys:
            value = value.replace(k, MASK)
        return value
    if isinstance(value, dict):
        return {k: _scrub(v, keys) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_scrub(v, keys) for v in value)
    return value


def scrub_error(text: str, overrides: Iterable[str]) -> str:
    """An error message fit to print: every known secret hidden, and no override value echoed back
    by Hydra's "append" hint (a misspelt key's value may be a key: ``+run.net.kye=...``)."""
    import re

    text = scrub(text, secret_values(overrides=overrides))
    return re.sub(r"(To append to your config use \+[^=\s]+)=[^\s;]+", r"\1=...", text)


def public_config(cfg: DictConfig) -> dict[str, Any]:
    """The resolved config as plain data, every secret value replaced by None (keys travel in the
    environment of the processes that need them, never in a file)."""
    data = OmegaConf.to_container(cfg, resolve=True)
    _null_secrets(data)
    return data   # type: ignore[return-value]


def _null_secrets(node: Any) -> None:
    if isinstance(node, dict):
        for k, v in node.items():
            if is_secret(str(k)) and not isinstance(v, dict | list):
                node[k] = None
            else:
                _null_secrets(v)
    elif isinstance(node, list):
        for v in node:
            _null_secrets(v)


def public_yaml(cfg: DictConfig) -> str:
    """``config.yaml``: the resolved config without its secrets."""
    return OmegaConf.to_yaml(OmegaConf.create(public_config(cfg)))


class _ScrubbedRecords:
    """A log record factory that hides secrets in every message (console job lists and the like)."""

    def __init__(self, base: Any, secrets: set[str]) -> None:
        self.base, self.secrets = base, secrets

    def __call__(self, *args: Any, **kwargs: Any) -> logging.LogRecord:
        rec = self.base(*args, **kwargs)
        text = rec.getMessage()
        clean = scrub(text, self.secrets)
        if clean != text:
            rec.msg, rec.args = clean, ()
        return rec


def scrub_logging(secrets: set[str]) -> None:
    """From now on, every log message of this process hides ``secrets`` (added to earlier ones)."""
    factory = logging.getLogRecordFactory()
    if isinstance(factory, _ScrubbedRecords):
        factory.secrets |= secrets
    elif secrets:
        logging.setLogRecordFactory(_ScrubbedRecords(factory, set(secrets)))


def child_env(keep: Mapping[str, str] | None = None, key_env: str | None = None) -> dict[str, str]:
    """The environment of a process the run starts: this package first on the path, no key variable
    of this process, only the keys in ``keep`` (a vehicle never gets the swarm key)."""
    env = {k: v for k, v in os.environ.items() if k not in KEY_ENVS and k != key_env}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(_PROJECT_ROOT), env.get("PYTHONPATH")]))
    env.update(keep or {})
    if key_env and key_env not in KEY_ENVS:   # so that the child hands it on to no process it starts
        env[KEY_VARS] = key_env
    return env


def hide_in_config(config: DictConfig) -> set[str]:
    """Hide every secret of a composed Hydra config in place — the task overrides, the override
    dir name, the secret keys' values — and in every later log message of this process; returns
    the secrets. For the master config of a sweep, which Hydra saves as ``multirun.yaml`` (each job
    composes its own config from its overrides, so nothing it runs with is changed)."""
    from omegaconf import flag_override

    overrides = list(OmegaConf.select(config, "hydra.overrides.task", default=None) or [])
    secrets = secret_values(config, overrides)
    scrub_logging(secrets)
    with flag_override(config, ["struct", "readonly"], [False, False]):
        if overrides:
            config.hydra.overrides.task = redact_overrides(overrides)
        dirname = OmegaConf.select(config, "hydra.job.override_dirname", default=None)
        if isinstance(dirname, str):
            config.hydra.job.override_dirname = scrub(dirname, secrets)
        for path in _secret_paths(OmegaConf.to_container(config, resolve=False)):
            OmegaConf.update(config, path, None, merge=False)
    return secrets


def _secret_paths(node: Any, prefix: str = "") -> Iterable[str]:
    if isinstance(node, dict):
        for k, v in node.items():
            path = f"{prefix}{k}"
            if is_secret(str(k)) and v not in (None, "") and not isinstance(v, dict | list):
                yield path
            else:
                yield from _secret_paths(v, path + ".")


# -- the manifest --------------------------------------------------------------------------------
def new_manifest(cfg: DictConfig, choices: dict[str, str], overrides: list[str], *, n_drones: int,
                 nodes: list[str], **extra: Any) -> dict[str, Any]:
    """``run.json`` as it stands before the first tick: ``failed`` until the run says otherwise."""
    from swarmbox.run import build

    manifest: dict[str, Any] = {
        "schema": SCHEMA_VERSION, "status": "failed", "reason": "", "traceback": None, "problems": [],
        "seed": int(cfg.seed), "choices": choices, "overrides": redact_overrides(overrides),
        "sim_time_s": 0.0, "wall_time_s": 0.0, "real_time_factor": None, "ticks": 0,
        "tick_s": 1.0 / cfg.run.tick_hz, "n_drones": n_drones, "nodes": nodes,
        "clocks": build.clock_settings(cfg), "versions": versions(), "git_sha": git_sha(),
        "started_at": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    manifest.update(extra)
    return manifest


def texts_overflowed(before: int) -> list[str]:
    """The problem to record when texts were logged as the overflow marker since ``before``."""
    if TEXTS.overflowed <= before:
        return []
    return [f"{TEXTS.overflowed - before} texts logged as {TEXTS.OVERFLOW!r}: the text table "
            f"holds {TEXTS.limit} texts"]


def close_logs(manifest: dict[str, Any], recorder: Any) -> None:
    """Finish the recorder's tables; tables that cannot be written (a full disk, a file size limit)
    fail the run with the cause and are listed under ``tables_not_written``."""
    try:
        recorder.close()
    except OSError as exc:
        add_reason(manifest, str(exc), fail=True)
    if recorder.not_written:
        manifest["tables_not_written"] = recorder.not_written


def add_reason(manifest: dict[str, Any], text: str, *, fail: bool = False) -> None:
    """Append ``text`` to the reason; ``fail``: the run is ``failed`` whatever it was."""
    manifest["reason"] = "; ".join(filter(None, [manifest.get("reason", ""), text]))
    if fail:
        manifest["status"] = "failed"


def node_outcome(results: dict[str, dict[str, Any]]) -> tuple[str, str]:
    """The status and reason of a run of node processes, by the single-process rules: the ground's
    outcome, except that an agent that failed (its hook or code raised) fails the run. An agent
    killed from outside is a lost drone, as a drone lost in flight is."""
    g = results[node_name(GROUND_ID)]
    status = g["status"] if g["status"] in ("ok", "aborted") else "failed"
    parts = [g.get("reason", "")] if status != "ok" or g.get("reason") else []
    if status == "failed" and g["status"] == "killed":
        parts = [f"ground {g['reason']}"]
    if g.get("lost_drones"):
        parts.append(f"lost drones {g['lost_drones']}")
    failed = []
    for name, r in results.items():
        if name == node_name(GROUND_ID):
            continue
        if r["status"] in ("killed", "failed"):
            parts.append(f"{name} {r['status']}: {r['reason']}")
            failed += [name] if r["status"] == "failed" else []
        elif r.get("first_exit"):
            parts.append(f"{name} {r['first_exit']}, restarted: {r['status']}")
    if failed:
        status = "failed"
        parts.insert(0, f"{', '.join(failed)} failed")
    return status, "; ".join(p for p in parts if p)


# -- run.json ------------------------------------------------------------------------------------
class RunJson:
    """``run.json`` of one run, its disk space reserved when the run starts.

    The reservation is a temporary file of :attr:`RESERVE` bytes written at the start; the record is
    written over it and renamed, so it fits even when the run's tables filled the disk. A record
    larger than the reservation that cannot be written whole is written without its bulky parts.
    """

    RESERVE = 256 << 10

    def __init__(self, run_dir: Path, secrets: Iterable[str] = (), *, name: str = "run.json",
                 reserve_bytes: int | None = None) -> None:
        self.path = run_dir / name
        self.tmp = run_dir / f".{name}.tmp"
        self.secrets = set(secrets)
        self.reserve_bytes = reserve_bytes
        self.reserved = False

    def reserve(self) -> None:
        """Claim the space (a failure is no error: the run then writes its record as usual)."""
        try:
            with open(self.tmp, "wb") as f:
                f.write(b" " * (self.reserve_bytes or self.RESERVE))
                f.flush()
                os.fsync(f.fileno())
            self.reserved = True
        except OSError:
            self.tmp.unlink(missing_ok=True)

    def write(self, manifest: dict[str, Any]) -> None:
        """Write the record (secrets hidden) into the reserved space, then rename it into place."""
        clean = scrub(manifest, self.secrets)
        manifest.update(clean)   # what the caller prints of it hides them too
        try:
            self._put(json.dumps(clean, indent=2, sort_keys=True, default=str))
        except OSError as exc:   # bigger than the space left: the record without its bulk
            slim = {k: v for k, v in clean.items() if k not in ("node_results", "traceback", "monitor")}
            slim["problems"] = [*slim.get("problems", []), f"run.json shortened: {exc.strerror or exc}"]
            self._put(json.dumps(slim, sort_keys=True, default=str))
        os.replace(self.tmp, self.path)

    def _put(self, text: str) -> None:
        data = text.encode()
        mode = "r+b" if self.tmp.exists() else "wb"
        with open(self.tmp, mode) as f:
            f.write(data)
            f.truncate(len(data))

    def discard(self) -> None:
        self.tmp.unlink(missing_ok=True)


def in_sweep() -> bool:
    """Whether this run is a job of a Hydra multirun."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    return HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN
