"""Claims on run and sweep directories: one process writes into a directory at a time.

A run (or a sweep) takes a kernel lock on a file in its directory before writing anything there and
holds it until its record is written; a second process into the same directory is refused at once,
and the lock ends with its process however that ends (a stale lock cannot block a later resume).
Nothing here removes a directory the run did not create.
"""

from __future__ import annotations

import os
from pathlib import Path

from omegaconf import DictConfig

from swarmbox.run.record import RunExistsError, RunJson, public_yaml, write_atomic


class Claim:
    """A directory claimed by this process: a lock file in it, held while the run (or sweep) writes.

    The lock is the kernel's (``flock``), so it ends with the process however it ends; a second
    process that tries to claim the same directory is refused at once. :meth:`undo` removes what
    the claim created — the directory itself only if it did not exist before.
    """

    def __init__(self, directory: Path, name: str = ".claim", what: str = "run") -> None:
        self.dir, self.file, self.what = Path(directory), Path(directory) / name, what
        self.existed = self.dir.exists()
        self._fd: int | None = None

    def acquire(self) -> Claim:
        """Create the directory if needed and lock it. Raises OSError if it cannot be written and
        :class:`RunExistsError` if another process holds it."""
        import fcntl

        self.dir.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(self.file, os.O_CREAT | os.O_RDWR, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
                os.close(fd)
                raise RunExistsError(f"{self.dir} is being written by another {self.what} "
                                     f"(pid {holder}); refusing to write into it") from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.file).st_ino
            except FileNotFoundError:
                same = False
            if same:   # else the holder removed the file while this process waited for it: again
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            self.file.unlink(missing_ok=True)
            os.close(self._fd)
            self._fd = None

    def undo(self) -> None:
        """Release, and remove the directory if this claim made it and nothing else is in it now."""
        self.release()
        if not self.existed:
            try:
                self.dir.rmdir()
            except OSError:
                pass


#: directories that existed before this process's Hydra made its output dirs (never removed)
_PREEXISTING: set[Path] = set()


def note_preexisting(*dirs: Path) -> None:
    """Remember which of ``dirs`` exist now, before Hydra creates its output directories."""
    _PREEXISTING.update(Path(d).resolve() for d in dirs if Path(d).exists())


def drop_if_made(path: Path) -> None:
    """Remove an empty output directory Hydra made for a job that wrote nothing — never one that
    existed before this command, and never a non-empty one."""
    if Path(path).resolve() in _PREEXISTING:
        return
    try:
        Path(path).rmdir()
    except OSError:
        pass


def claim_run(cfg: DictConfig, run_dir: Path, secrets: set[str]) -> tuple[Claim, RunJson]:
    """Claim ``run_dir`` for this run, write its ``config.yaml`` (no secrets) and reserve its
    ``run.json``. Raises :class:`RunExistsError` or, when the directory cannot be written, a
    ``ConfigError`` — after removing whatever it created."""
    from swarmbox.run.build import ConfigError

    claim = Claim(run_dir)
    run_json = RunJson(run_dir, secrets)
    try:
        claim.acquire()
        if (run_dir / "run.json").exists():   # finished by another process since the first look
            claim.release()
            raise RunExistsError(f"{run_dir} already holds a finished run; refusing to overwrite it")
        write_atomic(run_dir / "config.yaml", public_yaml(cfg))
    except OSError as exc:
        if isinstance(exc, RunExistsError):
            raise
        if run_dir.is_dir():
            (run_dir / "config.yaml").unlink(missing_ok=True)
        claim.undo()
        raise ConfigError(f"run directory {run_dir} (run.out_dir / hydra.run.dir) cannot be written: "
                          f"{exc.strerror or exc}") from None
    run_json.reserve()
    return claim, run_json
