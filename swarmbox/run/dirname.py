"""Run directory names that say what differs: the run's overrides, as Hydra's ``override_dirname``.

``results/runs/<time>_<overrides>`` for one run and ``<sweep dir>/<overrides>`` for a sweep's job,
where ``<overrides>`` is the job's command-line overrides sorted and joined as Hydra joins them
(``fault=gps_drift,fault.targets=[2],seed=3`` becomes ``fault=gps_drift,fault.targets=_2_,seed=3``),
with three differences that Hydra's own ``hydra.job.override_dirname`` cannot express:

- secrets never reach a path: any key whose last part contains ``key`` (``run.net.key``,
  ``backend.signing_key``) is left out, as are Hydra's own options (``hydra.*``) and the keys in
  ``hydra.job.config.override_dirname.exclude_keys`` (conf/config.yaml: the ones that do not change
  what a run is, such as ``run.resume``, so that a resumed sweep finds its runs under the same names);
- names are filesystem-safe: spaces are dropped, other characters than letters, digits and ``=,.+-~@``
  become ``_``;
- names are bounded (:data:`MAX_CHARS`): the longest values give way to a digest of themselves
  first, and only a name still too long is cut, ending in a digest of the whole; two different
  override lists never share a directory.

A job without overrides is named ``defaults``. Directory names are for people: every run's
metadata is read from its ``run.json``, never parsed back out of its directory name.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable

from omegaconf import OmegaConf

RESOLVER = "swarmbox_dirname"
MAX_CHARS = 160   # of the override part: with the time prefix, below the common 255-byte name limit
EMPTY = "defaults"
_UNSAFE = re.compile(r"[^A-Za-z0-9=,.+\-~@]")


def _key(override: str) -> str:
    return override.partition("=")[0].lstrip("+~")


def _hidden(key: str, exclude: set[str]) -> bool:
    return key in exclude or key == "hydra" or key.startswith(("hydra.", "hydra/")) or \
        "key" in key.rsplit(".", 1)[-1].lower()


def _digest(text: str, n: int) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def override_dirname(overrides: Iterable[str], exclude_keys: Iterable[str] = ()) -> str:
    """The directory name of a job with these task overrides (see the module docstring)."""
    exclude = {str(k) for k in exclude_keys}
    items = [_UNSAFE.sub("_", str(o).replace(" ", ""))
             for o in sorted(str(o) for o in overrides if not _hidden(_key(str(o)), exclude))]
    name = ",".join(items) or EMPTY
    # Too long: the longest values become digests first (``algo.drone._target_=#1f2e3d4c``), so that
    # the short ones that tell runs apart (``seed=3``) stay readable; the whole is cut only as a last resort.
    for i in sorted(range(len(items)), key=lambda i: -len(items[i])):
        if len(name) <= MAX_CHARS:
            return name
        key, _, value = items[i].partition("=")
        if len(value) > 9:
            items[i] = f"{key}=#{_digest(value, 8)}"
            name = ",".join(items)
    if len(name) > MAX_CHARS:
        name = f"{name[:MAX_CHARS - 11]}-{_digest(name, 10)}"
    return name


def register_resolver() -> None:
    """``${swarmbox_dirname:${hydra:overrides.task},${hydra:job.config.override_dirname.exclude_keys}}``."""
    if not OmegaConf.has_resolver(RESOLVER):
        OmegaConf.register_new_resolver(
            RESOLVER, lambda overrides, exclude=(): override_dirname(list(overrides), list(exclude)))
