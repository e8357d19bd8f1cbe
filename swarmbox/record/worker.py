"""The log writer as a process of its own: rows are encoded on another core.

With this writer the run's process only serialises each hand-over on its tick thread — the rare
tables' row tuples with :mod:`marshal` (~0.1 µs per row, the cheapest encoding of plain tuples), the
packed and state tables as the record batches they already are — and a background thread writes it
to a pipe (the interpreter lock is released meanwhile); this process decodes the rows, builds the
remaining record batches, appends them to the spill files and, at the end, cuts the per-node files
(:mod:`swarmbox.record.spill`). The recorder
starts it at its first hand-over, so a short run never starts it at all. Measured on a 2-core machine
it is no faster than encoding in the loop (``writer="thread"``, the default): the serialisation and the
pipe cost the loop about what the encoding would.

Protocol (pickled messages on stdin): ``("chunk", encoded)`` any number of times, then
``("close", [encoded tails], {node: tables}, logs_dir)``; the reply on stdout is the files not
written and the list of errors.
``python -m swarmbox.record.worker SPILL_DIR HOLD_BYTES`` runs the process side.
"""

from __future__ import annotations

import contextlib
import marshal
import os
import pickle
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from swarmbox.hal.launch import without_keys
from swarmbox.record.spill import Chunk, SpillFile, split

#: pipe capacity asked for (Linux caps it at /proc/sys/fs/pipe-max-size, 1 MiB by default)
PIPE_BYTES = 1 << 20


def encode(chunk: Chunk) -> tuple:
    """A chunk as plain data: its row tuples marshalled (a state chunk's record batch pickles itself)."""
    rows = marshal.dumps(chunk.rows) if chunk.data is None else None
    return (chunk.table, chunk.nodes, chunk.counts, rows, chunk.data)


def decode(data: tuple) -> Chunk:
    table, nodes, counts, rows, batch = data
    return Chunk(table, nodes, counts, marshal.loads(rows) if rows is not None else [], batch)


class WriterUnavailable(Exception):
    """The writer process could not take the first chunk (it did not start, or exited at once)."""


class WriterProcess:
    """The recorder's side: starts the process on first use, sends chunks, asks for the final cut."""

    def __init__(self, spill_root: Path, hold_bytes: int) -> None:
        self.spill_root, self.hold_bytes = spill_root, hold_bytes
        self._proc: subprocess.Popen | None = None
        self._sent = 0   # chunks the process has taken
        self.broken = False   # it died before it could finish the logs

    @property
    def started(self) -> bool:
        return self._proc is not None

    @staticmethod
    def pack(chunk: Chunk) -> bytes:
        """The message that carries ``chunk`` (built by the caller, on its own thread)."""
        return pickle.dumps(("chunk", encode(chunk)), protocol=pickle.HIGHEST_PROTOCOL)

    def send(self, chunk: Chunk, packed: bytes | None = None) -> None:
        """Called on the recorder's background thread with the chunk and its :meth:`pack`: blocks while
        the process is behind (the pipe is full).

        Raises :class:`WriterUnavailable` when the process cannot be started or dies before taking
        its first chunk (nothing is lost: the caller can write the chunk itself), OSError when it
        dies later."""
        if self._proc is None:
            try:
                self._start()
            except OSError as exc:
                raise WriterUnavailable(f"cannot start {sys.executable}: {exc}") from exc
        try:
            self._write_bytes(packed if packed is not None else self.pack(chunk))
        except OSError as exc:
            if not self._sent:
                self.kill()
                raise WriterUnavailable(f"it exited at start ({self._exit_note()})") from exc
            raise OSError(f"log writer process gone ({self._exit_note()})") from exc
        self._sent += 1

    def _write(self, message: tuple) -> None:
        """One message, in as few system calls as the pipe allows: the lock is released during each,
        and taking it back from a busy tick loop is what costs."""
        self._write_bytes(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))

    def _write_bytes(self, packed: bytes) -> None:
        data = memoryview(packed)
        fd = self._proc.stdin.fileno()
        while data:
            data = data[os.write(fd, data):]

    def finish(self, tails: Sequence[Chunk], nodes: Mapping[int, Sequence[str]],
               logs_root: Path) -> tuple[list[str], list[str]]:
        """Send the rows still buffered, have the process cut every per-node file; the files it could
        not write and its errors (:attr:`broken` set if it died first)."""
        proc = self._proc
        assert proc is not None
        try:
            self._write(("close", [encode(t) for t in tails], {n: list(t) for n, t in nodes.items()},
                         str(logs_root)))
            proc.stdin.close()
            failed, errors = pickle.load(proc.stdout)
        except (BrokenPipeError, EOFError, OSError, pickle.UnpicklingError):
            self.broken = True
            failed, errors = [], [f"log writer process failed ({self._exit_note()})"]
        proc.wait()
        proc.stdout.close()
        return failed, errors

    def kill(self) -> None:
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()

    def _start(self) -> None:
        package_root = str(Path(__file__).resolve().parents[2])   # the directory holding swarmbox/
        env = without_keys(os.environ)   # it encodes rows: it needs no key
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, env.get("PYTHONPATH")]))
        self._proc = subprocess.Popen([sys.executable, "-m", "swarmbox.record.worker", str(self.spill_root),
                                       str(self.hold_bytes)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        with contextlib.suppress(ImportError, AttributeError, OSError):   # Linux: fewer, larger writes
            import fcntl

            fcntl.fcntl(self._proc.stdin.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)

    def _exit_note(self) -> str:
        proc = self._proc
        code = proc.poll() if proc is not None else None
        return "still running" if code is None else f"exit code {code}"


def serve(spill_root: Path, hold_bytes: int, inp: Any, out: Any) -> int:
    """The process side: chunks into the spill until ``close``; then the cut, and the errors."""
    spill = SpillFile(spill_root, hold_bytes)
    errors: list[str] = []
    while True:
        try:
            message = pickle.load(inp)
        except EOFError:   # the run's process died: nothing to report to
            spill.close()
            return 1
        if message[0] == "chunk":
            chunk = None
            try:
                chunk = decode(message[1])
                spill.write(chunk)
            except Exception as exc:  # noqa: BLE001 - reported at close; later chunks still written
                where = f"{chunk.table} rows of nodes {chunk.nodes[:5]}..." if chunk else "a chunk"
                errors.append(f"{where}: {type(exc).__name__}: {exc}")
            continue
        _, tails, nodes, logs_root = message
        spill.close()
        failed: list[str] = []
        try:
            cut = {c.table: c for c in map(decode, tails)}
            errors = [f"log writer failed: {e}" for e in errors]
            failed, more = split(spill, cut, Path(logs_root), nodes)
            errors += more
        except Exception as exc:  # noqa: BLE001 - reported to the run
            errors.append(f"cutting the logs: {type(exc).__name__}: {exc}")
        pickle.dump((failed, errors), out)
        out.flush()
        return 0


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    # Ctrl-C and SIGTERM stop the run, which then closes its logs here; if the run dies, stdin ends
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)   # anything printed by a library goes to stderr, never into the reply
    return serve(Path(args[0]), int(args[1]), sys.stdin.buffer, out)


if __name__ == "__main__":
    sys.exit(main())
