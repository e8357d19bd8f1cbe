"""Reading a user-named input file truthfully: a size bound, and an error that says what the path is.

``read_text_bounded`` refuses anything but a regular file before opening it (a FIFO would block the
read, a device could stream forever) and names what it found instead: a directory, a FIFO, a device,
a socket, a symlink loop or a symlink to nothing.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path


class FileProblem(OSError):
    """Why a path cannot be read as an input file. ``exists``: the path names something."""

    def __init__(self, message: str, *, exists: bool = True) -> None:
        super().__init__(message)
        self.exists = exists

    def __str__(self) -> str:
        return str(self.args[0])


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def _size(n: int) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} bytes"


def read_text_bounded(path: Path, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them; anything else raises
    :class:`FileProblem` naming what is wrong."""
    try:
        st = os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise FileProblem("is a symlink loop (it resolves to itself)") from None
        if exc.errno == errno.ENOENT:
            if os.path.islink(path):
                raise FileProblem(f"is a symlink to a missing file ({os.readlink(path)})") from None
            raise FileProblem("no such file", exists=False) from None
        raise FileProblem(f"cannot read it ({exc.strerror})") from None
    for is_kind, what in _KINDS:
        if is_kind(st.st_mode):
            raise FileProblem(f"is {what}, not a regular file")
    if st.st_size > max_bytes:
        raise FileProblem(f"is {st.st_size} bytes ({_size(st.st_size)}), "
                          f"more than the {_size(max_bytes)} allowed")
    try:
        with open(path, "rb") as fh:
            data = fh.read(max_bytes + 1)   # the file may have grown since stat
    except OSError as exc:
        raise FileProblem(f"cannot read it ({exc.strerror})") from None
    if len(data) > max_bytes:
        raise FileProblem(f"is more than the {_size(max_bytes)} allowed")
    return data
