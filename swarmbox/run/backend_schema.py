"""Typed schemas of the ``backend`` config group, generated from the backends' parameter dataclasses.

One source of truth, as for faults: :class:`~swarmbox.hal.sim.params.SimParams`,
:class:`~swarmbox.hal.px4.backend.Px4Params` (+ :class:`~swarmbox.hal.px4.sitl.SitlOptions`) and
:class:`~swarmbox.hal.mavsim.backend.MavsimOptions` define each key and its type; this module turns
them into OmegaConf structured configs, stored in Hydra's ConfigStore as ``backend_<name>_schema``
(outside the ``backend`` group: a schema is no option) and listed first in each
``conf/backend/<name>.yaml``. So ``backend.mpc_xy_vel_max_m_s=fast`` or
``backend.max_speedd=5`` fails while the config is composed, with Hydra naming the key, and
:data:`PARAMS` lets the runner check value ranges before a run directory exists.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any, Optional

from omegaconf import MISSING

from swarmbox.hal.mavsim.options import MavsimOptions
from swarmbox.hal.px4.params import Px4Params
from swarmbox.hal.px4.sitl import SitlOptions
from swarmbox.hal.sim.params import SimParams


def _omegaconf_type(typ: Any) -> Any:
    """The nearest type OmegaConf 2.3 accepts: tuples -> lists, Mapping -> dict, ``X | None`` -> Optional."""
    origin, args = typing.get_origin(typ), typing.get_args(typ)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        base = _omegaconf_type(inner[0]) if len(inner) == 1 else Any
        return base if base is Any else Optional[base]   # noqa: UP045 - OmegaConf reads Optional[X]
    if origin is tuple:
        return list[_omegaconf_type(args[0])] if args else list[Any]
    if origin in (dict, Mapping, typing.Mapping) or typ is Mapping:
        return dict[str, _omegaconf_type(args[1])] if args else dict[str, Any]
    return typ


def _fields(cls: type, skip: tuple[str, ...] = ()) -> list[tuple[str, Any, Any]]:
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        if f.default is not dataclasses.MISSING:
            default = dataclasses.field(default=f.default)
        else:
            default = dataclasses.field(default_factory=f.default_factory)  # type: ignore[arg-type]
        out.append((f.name, _omegaconf_type(hints[f.name]), default))
    return out


def _schema(name: str, target: str, fields: list[tuple[str, Any, Any]], doc: str,
            base: type | None = None) -> type:
    head = [("name", str, dataclasses.field(default=name if base is None else MISSING)),
            ("_target_", str, dataclasses.field(default=target if base is None else MISSING))]
    cls = dataclasses.make_dataclass(f"{name.capitalize()}BackendConfig", head + fields,
                                     bases=(base,) if base else ())
    cls.__module__ = __name__
    cls.__doc__ = doc
    return cls


SitlConfig = dataclasses.make_dataclass("SitlConfig", _fields(SitlOptions))
SitlConfig.__module__ = __name__
_SimFields = dataclasses.make_dataclass("SimFields", [(n, Optional[t], dataclasses.field(default=None))  # noqa: UP045
                                                     for n, t, _ in _fields(SimParams)])
_SimFields.__module__ = __name__


def _px4_fields() -> list[tuple[str, Any, Any]]:
    out = []
    for name, typ, default in _fields(Px4Params):
        if name == "sitl":
            typ, default = SitlConfig, dataclasses.field(default_factory=SitlConfig)
        out.append((name, typ, default))
    return out


SimBackendConfig = _schema("sim", "swarmbox.hal.sim.backend.SimBackend", _fields(SimParams),
                           "Schema of ``backend=sim``: every SimParams field.")
Px4BackendConfig = _schema("px4", "swarmbox.hal.px4.backend.Px4Backend", _px4_fields(),
                           "Schema of ``backend=px4``: every Px4Params field.")
# Listed after ``px4`` in mavsim.yaml's defaults: the bridge's fields are MISSING here so that merging
# this schema keeps px4.yaml's values and only adds (and types) the mavsim keys.
MavsimBackendConfig = _schema(
    "mavsim", "swarmbox.hal.mavsim.backend.MavsimBackend",
    [(n, t, dataclasses.field(default=MISSING)) for n, t, _ in _px4_fields()]
    + [(n, t, d) if n != "sim" else (n, Optional[_SimFields], dataclasses.field(default=None))  # noqa: UP045
       for n, t, d in _fields(MavsimOptions)],
    "Schema of ``backend=mavsim``: the px4 bridge's fields plus MavsimOptions (``sim``: SimParams keys).",
    base=Px4BackendConfig)

#: backend config name -> (schema, parameter dataclass the backend builds from its keys)
SCHEMAS: dict[str, type] = {"sim": SimBackendConfig, "px4": Px4BackendConfig, "mavsim": MavsimBackendConfig}


def register(cs: Any) -> None:
    for name, schema in SCHEMAS.items():
        # outside the backend group, so that a schema is no backend= option (conf/backend/*.yaml
        # start from it as /backend_<name>_schema@_here_)
        cs.store(name=f"backend_{name}_schema", node=schema)
