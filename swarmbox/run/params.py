"""Typed algorithm params: the ``algo.params`` node checked against the algorithm's ``Params``.

An algorithm class may name a dataclass in its ``Params`` attribute (see :mod:`swarmbox.api`). Its
fields become the schema of ``algo.params``: OmegaConf merges the configured values onto it, so an
unknown key (a typo on the command line or in the algorithm's own YAML) or a value of the wrong type
fails here, before any node or vehicle exists, with a message naming the key. Values come out
converted to the declared types (``hover_s=5`` is the float 5.0). An algorithm without ``Params``
keeps untyped params, as before.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException


class ParamsError(ValueError):
    """``algo.params`` does not match the algorithm's ``Params``; the message names the key."""


def params_class(algo: DictConfig) -> type | None:
    """The ``Params`` dataclass declared by the configured drone and/or ground class, if any."""
    found: dict[str, type] = {}
    for role in ("drone", "ground"):
        node = algo.get(role)
        if node is None or not node.get("_target_"):
            continue
        try:
            cls = get_class(node["_target_"])
        except Exception:   # an unknown class is reported where it is instantiated
            continue
        schema = getattr(cls, "Params", None)
        if schema is not None:
            if not dataclasses.is_dataclass(schema):
                raise ParamsError(f"algo.{role}: {cls.__name__}.Params must be a dataclass, "
                                  f"got {schema!r}")
            found[role] = schema
    if len(set(found.values())) > 1:
        raise ParamsError(f"algo: drone and ground declare different Params "
                          f"({found['drone'].__name__} and {found['ground'].__name__})")
    return next(iter(found.values()), None)


def typed_params(algo: DictConfig) -> dict[str, Any]:
    """``algo.params`` as a plain dict, checked against and converted to the algorithm's schema."""
    raw = algo.get("params")
    # resolved against the whole config first (``${mission.obstacles}``), then typed
    values = OmegaConf.to_container(raw, resolve=True) if raw is not None else {}
    schema = params_class(algo)
    if schema is None:
        return values
    name = algo.get("name", "?")
    try:
        merged = OmegaConf.merge(OmegaConf.structured(schema), values)
        out = OmegaConf.to_container(merged, throw_on_missing=True)
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None) or getattr(exc, "key", None) or "?"
        raise ParamsError(f"algo.params.{key}: {_first_line(exc)} (algorithm '{name}', schema "
                          f"{schema.__module__}.{schema.__qualname__}; known keys: "
                          f"{', '.join(f.name for f in dataclasses.fields(schema))})") from exc
    return out


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0]
