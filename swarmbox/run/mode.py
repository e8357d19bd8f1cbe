"""Run or sweep, decided from the command line without composing the config an extra time.

Hydra composes the whole config once just to read ``hydra.mode`` before it composes it again for
the run (hydra-ecosystem/hydra#3440): a quarter of a second per command for SwarmBox's config. The
mode is ``-m`` / ``--multirun``, or a ``hydra.mode=RUN|MULTIRUN`` override on the command line; a
``hydra.mode`` written inside a config file is not consulted (no SwarmBox config sets one).
"""

from __future__ import annotations

from collections.abc import Sequence

from hydra.types import RunMode


def mode_from_overrides(overrides: Sequence[str]) -> RunMode | None:
    """The run mode a ``hydra.mode=...`` override asks for (the last one wins), else None (the flags
    decide). An unknown value gives None too, and Hydra then refuses the override, naming it."""
    for override in reversed(overrides):
        key, sep, value = override.partition("=")
        if sep and key.lstrip("+~") == "hydra.mode":
            return RunMode.__members__.get(value.strip().upper())
    return None


def install() -> None:
    """Make Hydra take the mode from the command line (:func:`mode_from_overrides`)."""
    from hydra._internal.hydra import Hydra

    def get_mode(self: Hydra, config_name: str | None, overrides: list[str]) -> RunMode | None:
        return mode_from_overrides(overrides)

    Hydra.get_mode = get_mode   # type: ignore[method-assign]
