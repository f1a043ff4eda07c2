"""Writing outputs safely: atomic files, sets of files published together, the output folder.

Every file is written to a temporary file beside its destination and moved into place when
complete; an existing file is never replaced unless asked to (``--overwrite``).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["OutputError", "output_folder", "publish", "writing", "atomic_write", "ResultSet", "check_outputs", "one_line"]


def _exists_message(path: Path) -> str:
    return f"{path} exists; pass --overwrite to replace it (refusing to overwrite it silently)"


def publish(tmp: str | Path, path: str | Path, *, overwrite: bool = False) -> None:
    """Move a finished temporary file into place with ordinary permissions.

    Without ``overwrite`` the move is a hard link, which fails if ``path`` appeared in the
    meantime: an existing file is never silently replaced.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600
    if overwrite:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise FileExistsError(_exists_message(path)) from None
    except OSError:  # a file system without hard links
        if path.exists():
            raise FileExistsError(_exists_message(path)) from None
        os.replace(tmp, path)
    else:
        os.unlink(tmp)


@contextlib.contextmanager
def writing(path: str | Path, *, overwrite: bool = False):
    """Yield a temporary path beside ``path``; when the block succeeds, :func:`publish` it there.

    Nothing is left behind on failure, and an existing file is refused up front.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(_exists_message(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        yield Path(tmp)
        publish(tmp, path, overwrite=overwrite)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write(path: str | Path, data: str | bytes, *, overwrite: bool = False) -> Path:
    """Write text or bytes to ``path`` atomically (see :func:`writing`).

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    with writing(path, overwrite=overwrite) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
    return Path(path)


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
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"--out {out}: cannot create the folder: {exc.strerror or exc}") from None
    return out


class ResultSet:
    """The output files of one run, published together or not at all.

    Every path is checked when the set is made (before any work): not a folder, not existing
    unless ``overwrite``, in a folder that exists (or is created, ``create_folders``) and can be
    written. Each file is written to a temporary file beside its destination (:meth:`temp`);
    :meth:`publish` moves them all into place, and if one move fails, removes those already moved
    (restoring what they replaced). Leaving the ``with`` block without publishing removes the
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
                    folder.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise OutputError(f"{who}: cannot create the folder {folder}: {exc.strerror or exc}") from None
            if not folder.is_dir():
                raise OutputError(f"{who}: the folder {folder} does not exist" if not folder.exists() else
                                  f"{who}: {folder} is not a folder")
            try:  # the real test of writability (permissions, read-only file systems)
                fd, probe = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
            except OSError as exc:
                raise OutputError(f"{who}: cannot write in the folder {folder}: {exc.strerror or exc}") from None
            os.close(fd)
            self._tmp[key] = Path(probe)

    def temp(self, key: str) -> Path:
        """The temporary file that becomes ``paths[key]`` on :meth:`publish`."""
        return self._tmp[key]

    def publish(self) -> None:
        """Move every temporary file into place, all or none."""
        done: list[tuple[Path, Path | None]] = []
        try:
            for key, path in self.paths.items():
                backup = None
                if self.overwrite and path.exists():
                    fd, b = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".bak")
                    os.close(fd)
                    os.replace(path, b)
                    backup = Path(b)
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

    def discard(self) -> None:
        """Remove the temporary files that were not published."""
        for tmp in self._tmp.values():
            if tmp.exists():
                tmp.unlink()

    def __enter__(self) -> "ResultSet":
        return self

    def __exit__(self, *exc) -> None:
        self.discard()


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
