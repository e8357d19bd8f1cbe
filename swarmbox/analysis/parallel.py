"""Run analyses in parallel processes, with progress: the end-of-sweep analysis of many runs.

Each run is analyzed on its own (unify, metrics, diagnosis), so runs spread over worker processes
with no shared state; results come back in the runs' order, so tables do not depend on which
worker finished first. Each worker keeps the memory a run frees for the next one
(:func:`_keep_freed_memory`). Progress is a rich bar on a terminal and plain lines otherwise.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, TypeVar

T = TypeVar("T")
SERIAL_BELOW = 3        # fewer runs than this: not worth starting processes
#: glibc's ``mallopt`` parameters (malloc.h) and what a worker sets them to (:func:`_keep_freed_memory`)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_BYTES, _TRIM_BYTES = 32 * 2**20, 64 * 2**20


def default_workers(n_items: int) -> int:
    """One process per idle core (cores minus the 1-minute load), at least 1, at most one per run.

    On a machine whose cores are already busy, extra processes only add start-up and contention
    (measured: 6 runs on 2 cores at load 17 took 30-37 s serially, 39-97 s with 2 workers).
    """
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    idle = int(cores - os.getloadavg()[0] + 0.5)
    return max(1, min(n_items, cores, idle))


def _keep_freed_memory() -> None:
    """Start of a worker process: the memory one run's analysis frees stays for the next run.

    An analysis allocates and frees arrays of a few MB by the dozen (each column of a 5-drone run's
    400,000 messages). By default glibc's malloc gives such blocks back to the system when they are
    freed (mapped blocks, and the heap's top past its trim threshold), and Arrow's allocator (mimalloc)
    decommits freed pages after 10 ms, so the next run faults every page in again: 10,000 to 17,000 page
    faults a 5-drone run, ~15 % of its CPU. Here blocks below 32 MiB come from malloc's heap, which keeps
    up to 64 MiB free at its top, and Arrow allocates from that malloc too; larger blocks (a large run's
    columns) are still mapped and returned as soon as they are freed. Nothing changes where the C
    library is not glibc (macOS, musl).
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (AttributeError, OSError, TypeError):   # no mallopt in this C library, or no C library
        return
    if mallopt(_M_MMAP_THRESHOLD, _MMAP_BYTES) and mallopt(_M_TRIM_THRESHOLD, _TRIM_BYTES):
        import pyarrow as pa  # here: a worker analyzes runs, this module itself needs no Arrow

        pa.set_memory_pool(pa.system_memory_pool())


class Reporter:
    """``reporter(done, total)``: a rich bar on a terminal, else a line every ``every_s`` and at the end."""

    def __init__(self, label: str, stream=None, every_s: float = 10.0) -> None:
        self.label, self.stream, self.every_s = label, stream or sys.stderr, every_s
        self.started = self.last = time.perf_counter()
        self._bar = None

    def __call__(self, done: int, total: int) -> None:
        if self._bar is None and getattr(self.stream, "isatty", lambda: False)():
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            bar = Progress(TextColumn(self.label), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                           console=Console(file=self.stream))
            bar.start()
            self._bar = (bar, bar.add_task(self.label, total=total))
        if self._bar is not None:
            self._bar[0].update(self._bar[1], completed=done, total=total)
            if done >= total:
                self._bar[0].stop()
            return
        now = time.perf_counter()
        if done >= total or now - self.last >= self.every_s:
            self.last = now
            elapsed = now - self.started
            eta = f", ETA {elapsed / done * (total - done):.0f} s" if 0 < done < total else ""
            print(f"{self.label}: {done}/{total} runs in {elapsed:.0f} s{eta}", file=self.stream, flush=True)


def map_runs(fn: Callable[..., T], items: Sequence[Any], *args: Any, workers: int | None = None,
             progress: Callable[[int, int], None] | None = None) -> list[T]:
    """``[fn(item, *args) for item in items]``, over ``workers`` processes (default: one per idle core)."""
    total = len(items)
    workers = default_workers(total) if workers is None else max(1, workers)
    out: list[Any] = [None] * total
    if workers == 1 or total < SERIAL_BELOW:
        for i, item in enumerate(items):
            out[i] = fn(item, *args)
            if progress:
                progress(i + 1, total)
        return out
    # spawn: safe whatever threads the calling process runs (Hydra, Ray, a progress monitor)
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_keep_freed_memory) as pool:
        futures = {pool.submit(fn, item, *args): i for i, item in enumerate(items)}
        for done, future in enumerate(as_completed(futures), start=1):
            out[futures[future]] = future.result()
            if progress:
                progress(done, total)
    return out
