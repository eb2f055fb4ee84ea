"""Output files and folders that are never half-written: the one atomic writer of every layer.

Every file the project writes goes through ``atomic_write_bytes`` / ``atomic_write_text``: the
bytes go to a temporary sibling (``.NAME.XXXX.tmp`` in the same directory, hence the same file
system), are flushed and fsynced, get the mode of an ordinary new file (0666 & ~umask, i.e. 0644
under the usual umask 022: ``mkstemp`` alone would leave 0600) and are renamed onto the target
(POSIX ``rename`` is atomic: a reader sees the old file or the new one, never a mixture). A crash
leaves at most a dot-file beside the target, which no reader takes for data.

Output folders (``simulate``, ``analyze``, ``acquire``, ``study``, ``run``):

- ``check_output_dir(path, force=..., resume_marker=...)`` refuses a non-empty target unless
  ``--force`` (which clears it) or, for a resumable run, a folder holding its journal;
- ``AtomicDir(target, force=...)`` builds a folder under a temporary sibling name and renames it
  onto the target when complete (``--force`` replaces a previous one only then), so a killed run
  never leaves anything under the target's name;
- ``DirLock(folder)`` is an O_EXCL lock file with the owner's pid: a second run on the same folder
  stops with an error naming the pid that holds it (a stale lock of a dead pid is taken over).

This module imports nothing of the project, so the analysis, the twin and the hardware layer can
all use it (the layering of pyproject.toml's import-linter contracts).
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
from pathlib import Path

__all__ = ["OutputError", "atomic_write_bytes", "atomic_write_text", "file_mode", "dir_mode", "check_output_dir",
           "clear_dir", "AtomicDir", "DirLock", "LOCK_NAME"]

LOCK_NAME = ".benchtwin.lock"


class OutputError(ValueError):
    """An output target that cannot be written as asked (exists, is locked, is not a folder)."""


def _umask() -> int:
    # os.umask can only be read by setting it; set and restore at once
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The mode of an ordinary new file: 0666 minus the process umask (0644 under umask 022)."""
    return 0o666 & ~_umask()


def dir_mode() -> int:
    """The mode of an ordinary new folder: 0777 minus the process umask (``mkdtemp`` gives 0700)."""
    return 0o777 & ~_umask()


def atomic_write_bytes(path: str | Path, data: bytes, *, fsync: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically (temporary sibling, fsync, chmod, rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            if fsync:
                os.fsync(f.fileno())
        os.chmod(tmp, file_mode())  # mkstemp creates 0600; outputs are ordinary files (issue #13)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def atomic_write_text(path: str | Path, text: str, *, fsync: bool = True) -> Path:
    """``atomic_write_bytes`` of UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"), fsync=fsync)


def _is_empty_dir(p: Path) -> bool:
    return p.is_dir() and not any(p.iterdir())


def clear_dir(path: str | Path) -> None:
    """Remove everything inside ``path`` (the folder itself stays); refuses a symlink."""
    p = Path(path)
    if p.is_symlink() or not p.is_dir():
        raise OutputError(f"{p}: expected a folder to clear (not a file or a symlink)")
    for child in p.iterdir():
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()


def check_output_dir(path: str | Path, *, force: bool = False, resume_marker: str | None = None,
                     resume: bool = False, what: str = "output folder") -> Path:
    """Make ``path`` ready as a new output folder, or refuse.

    - missing or empty: created, fine;
    - a file (or a symlink): always an error;
    - non-empty: an error unless ``force`` (everything in it is removed first) or ``resume`` with
      ``resume_marker`` (e.g. ``journal.jsonl``) present: a resumable run continues there.
    With ``resume_marker`` given and present but neither ``resume`` nor ``force``: an error that
    says how to resume or restart (nothing already measured is ever deleted unasked)."""
    p = Path(path)
    if p.is_symlink():
        raise OutputError(f"{p}: the {what} is a symlink; give a real folder")
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: expected a folder for the {what}, found a file")
    if resume:
        if resume_marker is None or not (p / resume_marker).is_file():
            raise OutputError(f"{p}: --resume: no {resume_marker or 'journal'} in it, nothing to resume "
                              "(run without --resume)")
        return p
    if p.is_dir() and not _is_empty_dir(p):
        if force:
            clear_dir(p)
        elif resume_marker is not None and (p / resume_marker).is_file():
            raise OutputError(f"{p}: holds {resume_marker} of an unfinished run (its readings are kept); "
                              "continue it with --resume, or start again with --force (deletes them)")
        else:
            raise OutputError(f"{p}: the {what} exists and is not empty; choose another, or --force to "
                              "replace its contents")
    p.mkdir(parents=True, exist_ok=True)
    return p


class AtomicDir:
    """Build an output folder under a temporary sibling name; rename it onto ``target`` when done.

    ::

        with AtomicDir(out, force=ns.force) as tmp:
            write_everything_into(tmp)
        # here `out` is complete; after an exception or a kill only `.out.partial-PID` may remain

    A non-empty ``target`` is refused at entry unless ``force``; with ``force`` the old folder is
    replaced only after the new one is complete (it is renamed aside, the new one renamed in, the
    old one removed), so ``--force`` never loses a good result to a failed run."""

    def __init__(self, target: str | Path, *, force: bool = False, what: str = "output folder"):
        self.target = Path(target)
        self.force = force
        self.what = what
        self.tmp: Path | None = None

    def __enter__(self) -> Path:
        t = self.target
        if t.is_symlink():
            raise OutputError(f"{t}: the {self.what} is a symlink; give a real folder")
        if t.exists() and not t.is_dir():
            raise OutputError(f"{t}: expected a folder for the {self.what}, found a file")
        if t.is_dir() and not _is_empty_dir(t) and not self.force:
            raise OutputError(f"{t}: the {self.what} exists and is not empty; choose another, or --force to "
                              "replace it")
        t.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(dir=t.parent, prefix=f".{t.name}.partial-{os.getpid()}-"))
        os.chmod(self.tmp, dir_mode())  # mkdtemp gives 0700; the result is an ordinary folder
        return self.tmp

    def __exit__(self, exc_type, *_) -> None:
        assert self.tmp is not None
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return
        t = self.target
        old = None
        if t.exists():
            if _is_empty_dir(t):
                t.rmdir()
            else:
                old = Path(tempfile.mkdtemp(dir=t.parent, prefix=f".{t.name}.old-{os.getpid()}-"))
                os.rmdir(old)
                os.replace(t, old)
        os.replace(self.tmp, t)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def final(self, p: str | Path) -> Path:
        """The path a file built under the temporary folder will have once renamed."""
        assert self.tmp is not None
        return self.target / Path(p).relative_to(self.tmp)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


class DirLock:
    """``folder/.benchtwin.lock`` created with O_CREAT|O_EXCL, holding the owner's pid.

    A second run on the same folder gets ``OutputError`` naming the pid; a lock whose pid no longer
    runs (the owner was killed -9) is taken over. Released on exit (removed if still ours)."""

    def __init__(self, folder: str | Path, what: str = "run"):
        self.path = Path(folder) / LOCK_NAME
        self.what = what
        self._held = False

    def acquire(self) -> "DirLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, file_mode())
            except FileExistsError:
                try:
                    pid = int(self.path.read_text(encoding="ascii").strip() or "0")
                except (OSError, ValueError, UnicodeDecodeError):
                    pid = 0
                if pid > 0 and pid != os.getpid() and _pid_alive(pid):
                    raise OutputError(f"{self.path.parent}: another {self.what} (pid {pid}) is writing this folder "
                                      f"(lock {self.path}); wait for it or stop it") from None
                if pid == os.getpid():
                    raise OutputError(f"{self.path.parent}: this process already holds the lock {self.path}") from None
                try:  # stale: its owner is gone
                    self.path.unlink()
                except FileNotFoundError:
                    pass
                continue
            with os.fdopen(fd, "w", encoding="ascii") as f:
                f.write(f"{os.getpid()}\n")
            self._held = True
            return self
        raise OutputError(f"{self.path}: could not take the lock (another run keeps re-creating it)")

    def release(self) -> None:
        if not self._held:
            return
        self._held = False
        try:
            if self.path.read_text(encoding="ascii").strip() == str(os.getpid()):
                self.path.unlink()
        except OSError as exc:
            if exc.errno != errno.ENOENT:
                raise

    def __enter__(self) -> "DirLock":
        return self.acquire()

    def __exit__(self, *_) -> None:
        self.release()
