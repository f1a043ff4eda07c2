"""Writing outputs safely: atomic files, sets of files published together, the output folder.

Every file is written to a temporary file beside its destination and moved into place when
complete; an existing file is never replaced unless asked to (``--overwrite``). The single file's
atomic write (:func:`atomic_write`, :func:`writing`, :func:`publish`) is :mod:`calib.files`' (the
calibration file is written at calib's edge), exported here beside the rest.
"""

from __future__ import annotations

import os
from pathlib import Path

from calib.files import (atomic_write, forget_created_folders, make_folder, publish,
                         remove_dead_writers_temporaries, take_back_created_folders, temporary_file, writing)

__all__ = ["OutputError", "output_folder", "publish", "writing", "atomic_write", "ResultSet", "check_outputs", "one_line",
           "FileLock", "LockHeld", "remove_stale_temporaries", "remove_dead_writers_temporaries", "temporary_file",
           "make_folder", "forget_created_folders", "take_back_created_folders", "NameReservation"]


class OutputError(ValueError):
    """An output path cannot be written; the message names it (and the flag that gave it)."""


def output_folder(out: str | Path) -> Path:
    """The output folder ``out`` (flag ``--out``), created if missing.

    Raises:
        OutputError: it is a file, or it cannot be created (the message names the flag).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: is a file, not a folder")
    try:
        make_folder(out)
    except OSError as exc:
        raise OutputError(f"--out {out}: cannot create the folder: {exc.strerror or exc}") from None
    return out


class ResultSet:
    """The output files of one run, published together or not at all.

    Every path is checked when the set is made (before any work): not a folder, not existing
    unless ``overwrite``, in a folder that exists (or is created, ``create_folders``) and can be
    written. Each file is written to a temporary file beside its destination (:meth:`temp`);
    :meth:`publish` moves them all into place, each by one atomic rename (an earlier file it replaces
    kept as a hard-linked backup until all are in place), and if one move fails, removes those
    already moved (restoring what they replaced). Leaving the ``with`` block without publishing removes the
    temporary files: an interrupted run leaves only hidden ``.*.tmp`` files, nothing that looks
    complete.

    Raises:
        FileExistsError: a path exists and ``overwrite`` is off.
        OutputError: a path cannot be written.
    """

    def __init__(self, paths: dict, *, overwrite: bool = False, flags: dict | None = None,
                 create_folders: bool = False):
        self.paths = {k: Path(v) for k, v in paths.items()}
        self.overwrite = overwrite
        self._tmp: dict[str, Path] = {}
        self._withdrawn: list[Path] = []  # dropped outputs whose earlier files publish removes (overwrite)
        try:
            self._check(flags or {}, create_folders)
        except BaseException:
            self.discard()
            raise

    def _check(self, flags: dict, create_folders: bool) -> None:
        for key, path in self.paths.items():
            who = f"{flags[key]} {path}" if key in flags else str(path)
            if path.is_dir():
                raise OutputError(f"{who}: is a folder, not a file")
            if path.exists() and not self.overwrite:
                raise FileExistsError(f"{who} exists; pass --overwrite to replace it (refusing to overwrite it "
                                      "silently)")
            folder = path.parent
            if create_folders and not folder.exists():
                try:
                    make_folder(folder)
                except OSError as exc:
                    raise OutputError(f"{who}: cannot create the folder {folder}: {exc.strerror or exc}") from None
            if not folder.is_dir():
                raise OutputError(f"{who}: the folder {folder} does not exist" if not folder.exists() else
                                  f"{who}: {folder} is not a folder")
            try:  # the real test of writability (permissions, read-only file systems)
                self._tmp[key] = temporary_file(path)
            except OSError as exc:
                raise OutputError(f"{who}: cannot write in the folder {folder}: {exc.strerror or exc}") from None

    def temp(self, key: str) -> Path:
        """The temporary file that becomes ``paths[key]`` on :meth:`publish`."""
        return self._tmp[key]

    def publish(self) -> None:
        """Move every temporary file into place, all or none."""
        done: list[tuple[Path, Path | None]] = []
        try:
            for path in self._withdrawn:  # an earlier run's file of an output this one does not write
                if path.exists():
                    backup = temporary_file(path, ".bak")
                    os.replace(path, backup)
                    done.append((path, backup))
            for key, path in self.paths.items():
                backup = _backup(path) if self.overwrite and path.exists() else None
                try:
                    publish(self._tmp[key], path, overwrite=self.overwrite)
                except BaseException:
                    if backup is not None:
                        os.replace(backup, path)
                    raise
                done.append((path, backup))
        except BaseException:
            for path, backup in reversed(done):
                if backup is not None:
                    os.replace(backup, path)
                elif path.exists():
                    path.unlink()
            raise
        for _, backup in done:
            if backup is not None:
                backup.unlink()

    def drop(self, key: str) -> None:
        """Leave ``paths[key]`` out of this set (an optional output not needed after all): its
        temporary file is removed and :meth:`publish` skips it; with ``overwrite`` an earlier file
        there is removed when the set is published (the outputs of a name are replaced together:
        no earlier run's file is left beside the new ones), restored if publishing fails."""
        tmp = self._tmp.pop(key)
        path = self.paths.pop(key)
        tmp.unlink(missing_ok=True)
        if self.overwrite:
            self._withdrawn.append(path)

    def discard(self) -> None:
        """Remove the temporary files that were not published."""
        for tmp in self._tmp.values():
            if tmp.exists():
                tmp.unlink()

    def __enter__(self) -> "ResultSet":
        return self

    def __exit__(self, *exc) -> None:
        self.discard()


def _backup(path: Path) -> Path:
    """A hidden backup of ``path`` beside it (``.bak``) that leaves ``path`` in place, a hard link:
    the file is then replaced by one atomic rename, so that ``path`` names the earlier file or the
    new one, complete, at every instant (a run killed then leaves the earlier one). Where the file
    system has no hard links, the file is moved there."""
    backup = temporary_file(path, ".bak")
    backup.unlink()
    try:
        os.link(path, backup)
    except OSError:
        os.replace(path, backup)
    return backup


def check_outputs(paths: dict, *, overwrite: bool) -> None:
    """Check output paths before any work (see :class:`ResultSet`); ``paths`` maps each flag to its
    path (``None``: not asked for).

    Raises:
        FileExistsError: a path exists and ``overwrite`` is off.
        OutputError: a path cannot be written (the message names the flag).
    """
    given = {flag: path for flag, path in paths.items() if path}
    with ResultSet(given, overwrite=overwrite, flags={flag: flag for flag in given}):
        pass


def one_line(exc: BaseException) -> str:
    """The exception's message on one line (OS errors with their path)."""
    if isinstance(exc, KeyError) and exc.args:
        text = str(exc.args[0])
    elif isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}"
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


class LockHeld(OSError):
    """The lock is held by another process (``holder``: its process id as written, or '')."""

    def __init__(self, path: Path, holder: str):
        super().__init__(f"{path} is held by another process{f' ({holder})' if holder else ''}")
        self.holder = holder


class FileLock:
    """An exclusive lock on ``path`` (POSIX ``flock``), the file holding the owner's process id
    for the message of a refused run.

    The system drops the lock when its holder ends, however it ends (a kill included), so a lock
    file left by a killed process blocks nothing, and of two processes started together exactly
    one takes it. The file is removed on :meth:`release`, while still locked; a process that
    opened it just before and then locks the removed file sees that the path no longer names it,
    and tries again.

    Raises:
        LockHeld: another process holds it.
        OSError: the file cannot be created or locked (the folder is not writable, a file system
            without locks).
    """

    def __init__(self, path: str | Path):
        import fcntl

        self.path = Path(path)
        while True:
            fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 32).decode(errors="replace").strip()
                os.close(fd)
                raise LockHeld(self.path, holder if holder.isdigit() else "") from None
            except OSError:
                os.close(fd)
                raise
            try:
                named, held = os.stat(self.path), os.fstat(fd)
                current = (named.st_dev, named.st_ino) == (held.st_dev, held.st_ino)
            except FileNotFoundError:
                current = False
            if current:
                break
            os.close(fd)  # locked a file its holder has just removed: take the one the path names now
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        self.fd = fd

    def release(self) -> None:
        """Remove the lock file and drop the lock (once)."""
        if self.fd is None:
            return
        self.path.unlink(missing_ok=True)
        os.close(self.fd)
        self.fd = None


def remove_stale_temporaries(folder: Path, name: str) -> list[Path]:
    """Remove the temporary files (``.{name}.*.tmp``, ``.{name}.*.bak``) an interrupted writer of
    ``folder/name`` left behind; call only while holding that name's lock. Returns those removed."""
    removed = []
    for pattern in (f".{name}.*.tmp", f".{name}.*.bak"):
        for path in Path(folder).glob(pattern):
            try:
                path.unlink()
            except FileNotFoundError:
                continue
            removed.append(path)
    return removed


class NameReservation:
    """The base name of a run's output files in folder ``out``, held by a lock
    (:class:`FileLock` on ``out/.{name}.lock``) until :meth:`release`.

    A default name (``explicit`` False) is numbered rather than overwritten (``base``,
    ``base_2``, ...: the first whose files, ``base + ext`` for each of ``extensions``, do not exist
    or may be overwritten, and whose lock is free), so two runs into one folder at the same time
    each get their own. An explicit name is never changed: one held by another run is refused.
    The lock goes with its process however it ends, so an interrupted run blocks nothing; the
    temporary files it left (``.{name}.*.tmp``) are removed when the name is taken again.

    Raises:
        OutputError: an explicit name another run holds, or a folder that cannot be written.
    """

    def __init__(self, out: Path, base: str, *, explicit: bool, overwrite: bool, extensions: tuple[str, ...]):
        self.out, self.lock = Path(out), None
        k = 1
        while True:
            cand = base if k == 1 else f"{base}_{k}"
            taken = any((self.out / f"{cand}{ext}").exists() for ext in extensions)
            if not taken or overwrite or explicit:
                try:
                    self.lock = FileLock(self.out / f".{cand}.lock")
                except LockHeld as exc:
                    if explicit:
                        who = f" (process {exc.holder})" if exc.holder else ""
                        raise OutputError(f"--name {cand}: another run{who} is writing {self.out / cand}.* "
                                          "now") from None
                except OSError as exc:
                    raise OutputError(f"--out {self.out}: cannot write in this folder: "
                                      f"{exc.strerror or exc}") from None
                else:
                    self.name = cand
                    remove_stale_temporaries(self.out, cand)
                    for ext in extensions:
                        remove_stale_temporaries(self.out, f"{cand}{ext}")
                    return
            k += 1

    def release(self) -> None:
        """Give the name back (remove its lock file)."""
        if self.lock is not None:
            self.lock.release()
        self.lock = None
