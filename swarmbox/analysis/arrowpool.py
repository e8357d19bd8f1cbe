"""The Arrow memory pool a large run is read from: one that gives freed memory back at once."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pyarrow as pa


@contextmanager
def arrow_pool(large: bool) -> Iterator[None]:
    """While a large run loads, Arrow allocates from a pool that gives freed memory back at once.

    The default pool (mimalloc) kept what the reads and the conversion to pandas freed: 1.4 GB beyond
    the 0.9 GB of frames of an 80 s 1,000-drone hover, growing with the run. jemalloc with no decay
    returns it (without jemalloc, the system allocator returns most); the default pool is restored
    after. A small run stays on the default pool: a sweep's worker reuses its few MB for the next run.
    """
    if not large:
        yield
        return
    before = pa.default_memory_pool()
    try:
        pa.jemalloc_set_decay_ms(0)
        pool = pa.jemalloc_memory_pool()
    except NotImplementedError:   # a pyarrow built without jemalloc
        pool = pa.system_memory_pool()
    pa.set_memory_pool(pool)
    try:
        yield
    finally:
        pa.set_memory_pool(before)
        before.release_unused()



def disk_bytes(paths: Iterable[Path]) -> int:
    """Total size of the files among ``paths`` that exist."""
    total = 0
    for path in paths:
        try:
            total += path.stat().st_size
        except OSError:
            pass   # absent: read_arrow says so
    return total
