"""Output files and folders that are never half-written: the one atomic writer of every layer.

Every file the project writes goes through ``atomic_write_bytes`` / ``atomic_write_text``: the
bytes go to a temporary sibling (``.NAME.XXXX.tmp`` in the same directory, hence the same file
system), are flushed and fsynced, get the mode of an ordinary new file (0666 & ~umask, i.e. 0644
under the usual umask 022: ``mkstemp`` alone would leave 0600) and are renamed onto the target
(POSIX ``rename`` is atomic: a reader sees the old file or the new one, never a mixture). A crash
leaves at most a dot-file beside the target, which no reader takes for data.

The one writing rule of every command (issue 31, docs/reliability.md), implemented here once:

- no existing file or folder is replaced without ``--force`` (``force=True`` in the API);
- ``--force`` never breaks a live lock: a folder is cleared or replaced only by the process that
  holds its lock, and a lock held by a live process is an error naming its pid, whatever the flags;
- an input is never an output: an output that is, contains or lies inside one of the command's
  inputs (compared after resolving symlinks, and by inode for hard links) is an error, even with
  ``--force`` (``check_not_input``);
- abandoned partial folders (``.OUT.partial-PID-START-*`` of a killed run) are removed by the next
  run into the same target, once it holds the target's lock, if their owner no longer runs.

Output files: ``check_output_target(path, force=..., inputs=...)``. Output folders:

- ``locked_output_dir(path, OutputFolder(what, owner, ...), force=..., resume=..., inputs=...)``
  (``simulate``, ``acquire``, ``import``, ``study``, ``suite``, ``emulate``): takes the folder's lock, then refuses a non-empty
  folder unless ``force`` (which clears it, the lock kept) or, for a resumable run, ``resume`` with
  its journal; ``check_output_dir`` is its check alone, for a caller that writes no lock;
- ``AtomicDir(target, force=..., inputs=...)`` (``analyze``, ``close-loop``, ``run``) takes the
  target's lock, builds the folder under a temporary sibling name and renames it onto the target
  when complete (``force`` replaces a previous one only then), so a killed run never leaves
  anything under the target's name;
- ``DirLock(folder)`` is an O_EXCL lock file with the owner's pid and start time: a second run on
  the same folder stops with an error naming the pid that holds it (a lock whose pid no longer
  runs, or runs a process started at another time, i.e. a reused pid, is taken over).

This module imports nothing of the project, so the analysis, the twin and the hardware layer can
all use it (the layering of pyproject.toml's import-linter contracts).
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

__all__ = ["OutputError", "DiskFullError", "disk_full", "raise_if_disk_full", "free_bytes", "atomic_write_bytes", "atomic_write_text", "stage_bytes", "commit_staged",
           "discard_staged", "file_mode", "dir_mode", "check_output_dir",
           "clear_dir", "AtomicDir", "DirLock", "LOCK_NAME", "check_not_input", "check_output_target",
           "OutputFolder", "locked_output_dir", "clean_abandoned_partials", "lock_owner"]

LOCK_NAME = ".benchtwin.lock"


class OutputError(ValueError):
    """An output target that cannot be written as asked (exists, is locked, is not a folder)."""


#: the errors of a full file system: no space left, disk quota exceeded
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})


def _size(n: float) -> str:
    """Bytes in the largest binary unit that keeps the number ≥ 1 (``12.0 MiB``)."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def free_bytes(path: str | Path) -> int | None:
    """Bytes an unprivileged writer may still use on the file system of ``path`` (or of its
    nearest existing parent); None where the OS cannot say."""
    p = Path(path)
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        st = os.statvfs(p)
    except (OSError, AttributeError):
        return None
    return int(st.f_bavail) * int(st.f_frsize)


class DiskFullError(OutputError):
    """A write failed because the file system is full (ENOSPC) or the quota is exceeded (EDQUOT):
    the file, the bytes it needed, the space left (exit 2, issue #31: a bare ``[Errno 28]`` named
    nothing). ``needed_bytes``: what that write needed; a command adds what the rest of its run
    needs and how to resume (``hint``)."""

    def __init__(self, path: str | Path, needed_bytes: int | None, reason: str, hint: str = ""):
        self.path = Path(path)
        self.needed_bytes = needed_bytes
        self.free_bytes = free_bytes(self.path.parent)
        self.reason = reason
        self.hint = hint
        super().__init__(self._text())

    def _text(self) -> str:
        need = f" writing {_size(self.needed_bytes)}" if self.needed_bytes is not None else ""
        free = f"; {_size(self.free_bytes)} free there" if self.free_bytes is not None else ""
        return f"{self.path}: the disk is full ({self.reason}){need}{free}" + (f"; {self.hint}" if self.hint else "")

    def with_hint(self, hint: str) -> "DiskFullError":
        """The same error, with what the command knows: the space the rest needs, how to resume."""
        err = DiskFullError(self.path, self.needed_bytes, self.reason, hint)
        err.__cause__ = self.__cause__
        return err


def raise_if_disk_full(exc: BaseException, path: str | Path, needed_bytes: int | None = None) -> None:
    """In an ``except`` clause: raise ``exc`` as a ``DiskFullError`` naming ``path`` if it is a full
    file system's error; else return (the caller re-raises ``exc``)."""
    err = disk_full(exc, path, needed_bytes)
    if err is exc:
        raise exc
    if err is not None:
        raise err from exc


def disk_full(exc: BaseException, path: str | Path, needed_bytes: int | None = None) -> DiskFullError | None:
    """``exc`` as a ``DiskFullError`` naming ``path`` if it is a full file system's error, else None."""
    if isinstance(exc, DiskFullError):
        return exc
    if isinstance(exc, OSError) and exc.errno in DISK_FULL_ERRNOS:
        err = DiskFullError(path, needed_bytes, exc.strerror or os.strerror(exc.errno))
        err.__cause__ = exc
        return err
    return None


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
    return commit_staged(stage_bytes(path, data, fsync=fsync), path)


def stage_bytes(path: str | Path, data: bytes, *, fsync: bool = True) -> Path:
    """The first half of ``atomic_write_bytes``: ``data`` in a complete temporary sibling of
    ``path`` (flushed, fsynced, mode set), returned; ``commit_staged`` renames it onto ``path``.
    Split so that a worker process can write a file's bytes while only its parent makes it
    appear (twin/render/pipeline.py: a worker outliving a killed run adds no file)."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise_if_disk_full(exc, path, len(data))
        raise
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            if fsync:
                os.fsync(f.fileno())
        os.chmod(tmp, file_mode())  # mkstemp creates 0600; outputs are ordinary files (issue #13)
    except BaseException as exc:
        discard_staged(tmp)
        raise_if_disk_full(exc, path, len(data))
        raise
    return Path(tmp)


def commit_staged(tmp: str | Path, path: str | Path) -> Path:
    """Rename a file ``stage_bytes`` wrote onto its target (atomic); removes it if that fails."""
    try:
        os.replace(tmp, path)
    except BaseException:
        discard_staged(tmp)
        raise
    return Path(path)


def discard_staged(tmp: str | Path) -> None:
    """Remove a staged file that will not be committed (missing: nothing to do)."""
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass


def atomic_write_text(path: str | Path, text: str, *, fsync: bool = True) -> Path:
    """``atomic_write_bytes`` of UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"), fsync=fsync)


# ----------------------------------------------------------------------------- owners and locks


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def _start_time(pid: int) -> int | None:
    """The start time of process ``pid`` (clock ticks since boot, field 22 of /proc/PID/stat), or
    None where /proc does not tell. A pid and its start time name one process: a pid reused by a
    later process has another start time."""
    try:
        with open(f"/proc/{int(pid)}/stat", "rb") as f:
            stat = f.read()
        return int(stat[stat.rindex(b")") + 2:].split()[19])  # fields after "pid (comm)" start at field 3
    except (OSError, ValueError, IndexError):
        return None


def _owner_alive(pid: int, start: int | None) -> bool:
    """Is the process that wrote ``pid`` (and ``start``, when recorded) still running?"""
    if pid <= 0 or not _pid_alive(pid):
        return False
    if start is None:
        return True
    now = _start_time(pid)
    return now is None or now == start


def _owner_token() -> str:
    """``PID START`` of this process: what a lock file and a partial folder's name record."""
    return f"{os.getpid()} {_start_time(os.getpid()) or 0}"


def _read_owner(lock: Path) -> tuple[int, int | None]:
    """(pid, start time or None) written in a lock file; (0, None) when unreadable (stale)."""
    try:
        parts = lock.read_text(encoding="ascii").split()
        pid = int(parts[0]) if parts else 0
        start = int(parts[1]) if len(parts) > 1 and int(parts[1]) > 0 else None
        return pid, start
    except (OSError, ValueError, UnicodeDecodeError):
        return 0, None


def lock_owner(folder: str | Path) -> int | None:
    """The pid of the live process holding ``folder``'s lock, or None (no lock, or a stale one)."""
    lock = Path(folder) / LOCK_NAME
    if not lock.is_file() or lock.is_symlink():
        return None
    pid, start = _read_owner(lock)
    return pid if _owner_alive(pid, start) else None


def _live_lock_error(folder: Path, pid: int, what: str) -> OutputError:
    return OutputError(f"{folder}: another {what} (pid {pid}) is writing this folder (lock {folder / LOCK_NAME}); "
                       "wait for it or stop it (--force never breaks a live lock)")


class DirLock:
    """``folder/.benchtwin.lock`` created with O_CREAT|O_EXCL, holding the owner's pid and start time.

    A second run on the same folder gets ``OutputError`` naming the pid; a lock whose owner no
    longer runs (killed -9, or its pid reused by a process started later) is taken over. Released
    on exit (removed if still ours)."""

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
                pid, start = _read_owner(self.path)
                if pid == os.getpid():
                    raise OutputError(f"{self.path.parent}: this process already holds the lock {self.path}") from None
                if _owner_alive(pid, start):
                    raise _live_lock_error(self.path.parent, pid, self.what) from None
                try:  # stale: its owner is gone
                    self.path.unlink()
                except FileNotFoundError:
                    pass
                continue
            with os.fdopen(fd, "w", encoding="ascii") as f:
                f.write(_owner_token() + "\n")
            self._held = True
            return self
        raise OutputError(f"{self.path}: could not take the lock (another run keeps re-creating it)")

    def release(self) -> None:
        if not self._held:
            return
        self._held = False
        try:
            if _read_owner(self.path)[0] == os.getpid():
                self.path.unlink()
        except OSError as exc:
            if exc.errno != errno.ENOENT:
                raise

    def __enter__(self) -> "DirLock":
        return self.acquire()

    def __exit__(self, *_) -> None:
        self.release()


# ----------------------------------------------------------------------------- inputs are never outputs


def _real(p: Path) -> Path:
    """``p`` with every symlink resolved (a missing tail is kept as written)."""
    return Path(os.path.realpath(p))


def check_not_input(out: str | Path, inputs: Iterable[str | Path | None], what: str = "output") -> None:
    """Refuse an output that is one of the command's inputs, contains one, or lies inside one.

    Compared after resolving symlinks (``os.path.realpath``), and by device and inode
    (``os.path.samefile``: a hard link, or another name of a folder). Always an error, with or
    without ``--force``: the command would destroy or change what it reads."""
    o = Path(out)
    ro = _real(o)
    for i in inputs:
        if i is None:
            continue
        ip = Path(i)
        if not (ip.exists() or ip.is_symlink()):
            continue
        ri = _real(ip)
        same = ro == ri
        if not same and o.exists():
            try:
                same = os.path.samefile(o, ip)
            except OSError:
                same = False
        if same:
            raise OutputError(f"{o}: the {what} is the input {ip}; write it elsewhere (an input is never an "
                              "output, even with --force)")
        if ro.is_relative_to(ri):
            raise OutputError(f"{o}: the {what} lies inside the input {ip}; write it elsewhere (an input is never "
                              "an output, even with --force)")
        if ri.is_relative_to(ro):
            raise OutputError(f"{o}: the {what} contains the input {ip}; write it elsewhere (an input is never an "
                              "output, even with --force)")


def check_output_target(path: str | Path, *, force: bool = False, inputs: Iterable[str | Path | None] = (),
                        what: str = "output file") -> Path:
    """The rule for an output file (``certificate -o``, ``calibrate-twin -o``, a live page): never
    one of the inputs (even with ``force``), never a folder, and an existing file (or symlink) is
    replaced only with ``force``. Returns the path; the caller writes it with ``atomic_write_*``."""
    p = Path(path)
    check_not_input(p, inputs, what)
    if p.is_dir() and not p.is_symlink():
        raise OutputError(f"{p}: the {what} is a folder; give a file name")
    if (p.exists() or p.is_symlink()) and not force:
        raise OutputError(f"{p}: the {what} exists; choose another, or --force to replace it")
    return p


# ----------------------------------------------------------------------------- output folders


def _is_empty_dir(p: Path) -> bool:
    """A folder holding nothing but (at most) its lock file."""
    return p.is_dir() and all(c.name == LOCK_NAME for c in p.iterdir())


def clear_dir(path: str | Path) -> None:
    """Remove everything inside ``path`` (the folder itself stays); refuses a symlink, and a folder
    whose lock a live process other than this one holds. The lock file of this process stays."""
    p = Path(path)
    if p.is_symlink() or not p.is_dir():
        raise OutputError(f"{p}: expected a folder to clear (not a file or a symlink)")
    owner = lock_owner(p)
    if owner is not None and owner != os.getpid():
        raise _live_lock_error(p, owner, "run")
    for child in p.iterdir():
        if child.name == LOCK_NAME and owner == os.getpid():
            continue
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()


def _check_folder_kind(p: Path, what: str) -> None:
    if p.is_symlink():
        raise OutputError(f"{p}: the {what} is a symlink; give a real folder")
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: expected a folder for the {what}, found a file")


def check_output_dir(path: str | Path, *, force: bool = False, resume_marker: str | None = None,
                     resume: bool = False, what: str = "output folder", complete_marker: str | None = None) -> Path:
    """Make ``path`` ready as a new output folder, or refuse.

    - missing or empty: created, fine;
    - a file (or a symlink): always an error;
    - locked by a live process other than this one: always an error naming its pid;
    - non-empty: an error unless ``force`` (everything in it is removed first, this process's lock
      file excepted) or ``resume`` with ``resume_marker`` (e.g. ``journal.jsonl``) present: a
      resumable run continues there.
    With ``resume_marker`` given and present but neither ``resume`` nor ``force``: an error that
    says how to resume or restart (nothing already measured is ever deleted unasked); but when
    ``complete_marker`` (e.g. ``manifest.json``, written last) is present too, the run finished, and
    the error says so (another folder, or ``--force``), not that it could be continued (issue 34).
    ``locked_output_dir`` takes the lock first, then runs this check."""
    p = Path(path)
    _check_folder_kind(p, what)
    owner = lock_owner(p) if p.is_dir() else None
    if owner is not None and owner != os.getpid():
        raise _live_lock_error(p, owner, "run")
    if resume:
        if resume_marker is None or not (p / resume_marker).exists():
            raise OutputError(f"{p}: --resume: no {resume_marker or 'journal'} in it, nothing to resume "
                              "(run without --resume)")
        return p
    if p.is_dir() and not _is_empty_dir(p):
        if force:
            clear_dir(p)
        elif complete_marker is not None and (p / complete_marker).is_file():
            raise OutputError(f"{p}: holds a complete {what.removesuffix(' folder')} ({complete_marker} written: the run "
                              "finished); choose another folder, or --force to replace it")
        elif resume_marker is not None and (p / resume_marker).exists():
            raise OutputError(f"{p}: holds {resume_marker} of an unfinished run (its readings are kept); "
                              "continue it with --resume, or start again with --force (deletes them)")
        else:
            raise OutputError(f"{p}: the {what} exists and is not empty; choose another, or --force to "
                              "replace its contents")
    p.mkdir(parents=True, exist_ok=True)
    return p


@dataclass(frozen=True)
class OutputFolder:
    """What kind of output folder a command writes in place: what its messages call it (``what``), who
    holds its lock (``owner``, written in the lock file), the file whose presence makes it resumable
    with ``resume`` (``resume_marker``, e.g. the journal) and the file written last, whose presence
    says the run finished (``complete_marker``, e.g. ``manifest.json``); ``check_output_dir``."""

    what: str = "output folder"
    owner: str = "run"
    resume_marker: str | None = None
    complete_marker: str | None = None


@contextlib.contextmanager
def locked_output_dir(path: str | Path, folder: OutputFolder, *, force: bool = False, resume: bool = False,
                      inputs: Iterable[str | Path | None] = ()) -> Iterator[Path]:
    """An output folder of the kind ``folder`` written in place, held under its lock for the whole block.

    The order is what makes ``--force`` safe: the inputs are checked, the lock is taken (a live
    owner: an error naming its pid, whatever the flags), and only then is the folder checked and,
    with ``force``, cleared (``check_output_dir``). A folder this call created is removed again if
    the block fails before writing anything into it."""
    p = Path(path)
    check_not_input(p, inputs, folder.what)
    _check_folder_kind(p, folder.what)
    created = not p.exists()
    p.mkdir(parents=True, exist_ok=True)
    lock = DirLock(p, folder.owner)
    try:
        lock.acquire()
        try:
            check_output_dir(p, force=force, resume=resume, resume_marker=folder.resume_marker, what=folder.what,
                             complete_marker=folder.complete_marker)
            yield p
        finally:
            lock.release()
    finally:
        if created:
            with contextlib.suppress(OSError):
                p.rmdir()  # only if empty: nothing was written


#: ``.NAME.partial-PID-START-XXXX`` (AtomicDir's build folder) or ``.NAME.old-PID-START-XXXX`` (the
#: replaced output being removed); folders of earlier versions lack START
_PARTIAL = re.compile(r"\.(partial|old)-(\d+)-(?:(\d+)-)?[A-Za-z0-9_]+")


def clean_abandoned_partials(target: str | Path) -> list[Path]:
    """Remove the partial folders a killed run left beside ``target`` (``.T.partial-PID-START-*``,
    ``.T.old-PID-START-*``) whose owner no longer runs (its pid is gone, or now names a process
    started at another time); returns those removed. Called by ``AtomicDir`` while it holds
    ``target``'s lock, so no live run of this version is building any of them."""
    t = Path(target)
    removed: list[Path] = []
    prefix = f".{t.name}"
    try:
        siblings = list(t.parent.iterdir())
    except OSError:
        return removed
    for s in siblings:
        if not s.name.startswith(prefix) or s.is_symlink() or not s.is_dir():
            continue
        m = _PARTIAL.fullmatch(s.name[len(prefix):])
        if m is None:
            continue
        pid, start = int(m.group(2)), (int(m.group(3)) if m.group(3) else None)
        if start == 0:
            start = None
        if pid == os.getpid() or _owner_alive(pid, start):
            continue
        shutil.rmtree(s, ignore_errors=True)
        removed.append(s)
    return removed


class AtomicDir:
    """Build an output folder under a temporary sibling name; rename it onto ``target`` when done.

    ::

        with AtomicDir(out, force=ns.force, inputs=[ns.dataset]) as tmp:
            write_everything_into(tmp)
        # here `out` is complete; after an exception or a kill only `.out.partial-PID-START-*`
        # may remain, which the next run into `out` removes

    ``target``'s lock (``DirLock``) is held from entry to the end: a second run into the same
    target is refused while the first one lives, whatever ``force`` says. An input the output would
    be, contain or lie in is refused (``check_not_input``). A non-empty ``target`` is refused at
    entry unless ``force``; with ``force`` the old folder is replaced only after the new one is
    complete (it is renamed aside, the new one renamed in, the old one removed), so ``--force``
    never loses a good result to a failed run."""

    def __init__(self, target: str | Path, *, force: bool = False, what: str = "output folder",
                 owner: str = "run", inputs: Iterable[str | Path | None] = ()):
        self.target = Path(target)
        self.force = force
        self.what = what
        self.inputs = list(inputs)
        self.tmp: Path | None = None
        self._lock = DirLock(self.target, owner)
        self._created = False

    def __enter__(self) -> Path:
        t = self.target
        check_not_input(t, self.inputs, self.what)
        _check_folder_kind(t, self.what)
        self._created = not t.exists()
        t.mkdir(parents=True, exist_ok=True)
        try:
            self._lock.acquire()
            if not _is_empty_dir(t) and not self.force:
                raise OutputError(f"{t}: the {self.what} exists and is not empty; choose another, or --force to "
                                  "replace it")
            clean_abandoned_partials(t)
            pid, start = _owner_token().split()
            self.tmp = Path(tempfile.mkdtemp(dir=t.parent, prefix=f".{t.name}.partial-{pid}-{start}-"))
            os.chmod(self.tmp, dir_mode())  # mkdtemp gives 0700; the result is an ordinary folder
        except BaseException:
            self._release()
            raise
        return self.tmp

    def _release(self) -> None:
        self._lock.release()
        if self._created:
            with contextlib.suppress(OSError):
                self.target.rmdir()  # only if still empty

    def __exit__(self, exc_type, *_) -> None:
        assert self.tmp is not None
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self._release()
            return
        t = self.target
        # the new folder carries this process's lock, so the target stays locked across the swap
        with open(self.tmp / LOCK_NAME, "w", encoding="ascii") as f:
            f.write(_owner_token() + "\n")
        pid, start = _owner_token().split()
        old = Path(tempfile.mkdtemp(dir=t.parent, prefix=f".{t.name}.old-{pid}-{start}-"))
        os.rmdir(old)
        os.replace(t, old)
        os.replace(self.tmp, t)
        self._created = False
        self._lock.release()
        shutil.rmtree(old, ignore_errors=True)

    def final(self, p: str | Path) -> Path:
        """The path a file built under the temporary folder will have once renamed."""
        assert self.tmp is not None
        return self.target / Path(p).relative_to(self.tmp)
