"""What the jobs of this process did beyond their run.json: jobs never started, jobs refused.

The basic launcher runs a sweep's jobs in this process, so the end-of-sweep summary can read it.
"""

from __future__ import annotations

from collections.abc import Callable

from swarmbox.run.record import redact_overrides, scrub_error

_state: dict[str, list] = {"entered": [], "not_started": [], "invalid": []}
_on_enter: list[Callable[[], None]] = []


def on_enter(fn: Callable[[], None]) -> None:
    """Call ``fn`` once the config has composed (the first job or the sweep starts)."""
    _on_enter.append(fn)


def entered() -> None:
    _state["entered"].append(True)
    while _on_enter:
        _on_enter.pop()()


def any_entered() -> bool:
    return bool(_state["entered"])


def not_started(overrides: list[str]) -> None:
    _state["not_started"].append(" ".join(redact_overrides(overrides)))


def invalid(overrides: list[str], reason: str) -> None:
    """A job refused as bad input (its overrides and the reason, keys hidden: both reach sweep.json)."""
    _state["invalid"].append((" ".join(redact_overrides(overrides)), scrub_error(reason, overrides)))


def jobs_not_started() -> list[str]:
    return list(_state["not_started"])


def jobs_invalid() -> list[tuple[str, str]]:
    return list(_state["invalid"])
