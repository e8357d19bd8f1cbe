"""The sim backend's per-step arithmetic as compiled functions (numba), for long runs.

One :meth:`SimBackend.step` runs about sixty numpy calls around pymunk's: the cascaded controller
(:mod:`swarmbox.hal.sim.control`), the vertical integration (``SimBackend._integrate_vertical``), the
GNSS corrections (:mod:`swarmbox.hal.sim.sensors`), the estimates and the battery. At a few drones each
call costs far more than its arithmetic (a five-drone delivery run spent a third of its tick there).
``fleet_jit`` does the same work as three loops over the drones — ``fleet_update`` (controller and
vertical integration), ``gnss_correct`` (after the noise draw, which stays numpy's, so the random
streams are untouched) and ``after_step`` — compiled by numba on first use and cached on disk.

The numpy code stays the reference: these loops repeat its operations one for one and in the same
order (``np.maximum``/``np.minimum`` as their NaN-propagating comparisons, ``hypot`` from the C
library, Python's float ``%`` as numpy's), so both give bit-identical states;
``tests/hal/sim/test_kernel.py`` flies every mode both ways and compares every array after every
step. Which path a run takes is ``backend.jit`` (:class:`~swarmbox.hal.sim.params.SimParams`): under
the default ``auto`` the kernel takes over once the process has flown ``JIT_AFTER_STEPS`` steps on
numpy (numba installed), and from the first step of every later run in that process.
"""

from __future__ import annotations

import importlib.util
from types import ModuleType

#: "auto": the kernel is loaded once this process has flown this many fleet steps on numpy (about
#: 250 simulated seconds at 40 Hz, over one run or several). Loading costs about a quarter of a second
#: (importing numba, reading the compiled code from its cache) and the kernel saves 15-40 us a step,
#: so a sweep worker pays it once for every run after; short runs never load it.
JIT_AFTER_STEPS = 10_000

_kernel: ModuleType | None = None
_numpy_steps = 0


def installed() -> bool:
    """Whether numba is installed (found, not imported: importing it takes a quarter of a second)."""
    return importlib.util.find_spec("numba") is not None


def loaded() -> ModuleType | None:
    """The kernel if this process has loaded it already, else None."""
    return _kernel


def compiled() -> ModuleType:
    """The kernel module (``fleet_jit``: ``fleet_update``, ``gnss_correct``, ``after_step``), compiled
    on the first call ever and loaded from numba's on-disk cache after that. Raises ImportError when
    numba is missing."""
    global _kernel
    if _kernel is None:
        from swarmbox.hal.sim import fleet_jit  # heavy: only when a run asks for it

        _kernel = fleet_jit
    return _kernel


def count_numpy_step() -> bool:
    """Count one fleet step flown on numpy; True once the process has flown ``JIT_AFTER_STEPS``."""
    global _numpy_steps
    _numpy_steps += 1
    return _numpy_steps >= JIT_AFTER_STEPS
