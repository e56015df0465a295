"""One run at a time in a participant's folder: an operating-system file lock.

A second ``fovexp run`` on the same folder (say a ``--resume`` while the session still runs)
would log every trial twice, so a run holds :data:`LOCK_FILE` for as long as it uses the
folder. The operating system drops the lock when the process dies, so a killed session can be
resumed at once. A folder the run created and wrote nothing to (a missing tracker, a failed
display check) is removed again when the lock is let go.
"""

from __future__ import annotations

from pathlib import Path

from filelock import FileLock, Timeout

from fovexp import FovexpError

#: held (an OS file lock) in the participant's folder while a run uses it
LOCK_FILE = ".fovexp-run.lock"


class FolderLock:
    """Create ``folder`` (and its missing parents) and hold its lock; :meth:`release` lets go.

    ``what`` names the folder's owner in the refusal (participant and experiment); ``root``
    is the results root the operator gave (named when the folder cannot be created)."""

    def __init__(self, folder: Path, what: str, root: Path | str) -> None:
        self.folder = Path(folder)
        self.created = [p for p in (*reversed(self.folder.parents), self.folder)
                        if not p.exists()]
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FovexpError(f"--results {root}: cannot create {self.folder}: "
                              f"{exc.strerror}") from None
        lock: FileLock | None = FileLock(str(self.folder / LOCK_FILE), thread_local=False,
                                         is_singleton=True)
        try:
            lock.acquire(timeout=0)
        except Timeout:
            raise FovexpError(
                f"{self.folder} is in use by another fovexp run ({what}): wait for it to end, "
                "or stop it first") from None
        self._lock = lock

    @property
    def held(self) -> bool:
        return self._lock is not None

    def release(self) -> None:
        """Let go of the lock (once; later calls do nothing); remove the folders this run
        created when nothing but the lock file is in them."""
        lock, self._lock = self._lock, None
        if lock is None:
            return
        if lock.is_locked:
            lock.release()
        if lock.is_locked:  # still held by another user of this process (a singleton lock)
            return
        if [p for p in self.folder.iterdir() if p.name != LOCK_FILE]:
            return
        (self.folder / LOCK_FILE).unlink(missing_ok=True)
        for p in reversed(self.created):
            try:
                p.rmdir()
            except OSError:  # not empty (another participant's folder appeared): keep it
                break


__all__ = ["LOCK_FILE", "FolderLock"]
