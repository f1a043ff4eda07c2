"""Files at calib's edge: atomic writing and reading text and JSON with one-line errors.

The calibration file (:mod:`calib.calibration`) is read and written here; ``pipeline.formats``
writes every other output with the same helpers (:mod:`pipeline.formats.outputs`). Every file is
written to a temporary file beside its destination and moved into place when complete; an
existing file is never replaced unless asked to (``--overwrite``).
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import tempfile
from pathlib import Path

__all__ = ["publish", "writing", "atomic_write", "read_text_file", "read_json_file", "make_folder", "CREATED_FOLDERS",
           "forget_created_folders", "take_back_created_folders", "temporary_file", "remove_dead_writers_temporaries"]


#: Folders this process created for its outputs since :func:`forget_created_folders`, outermost
#: first: a refused command takes them back (:func:`take_back_created_folders`).
CREATED_FOLDERS: list[Path] = []


def make_folder(folder: str | Path) -> Path:
    """``folder`` created with its missing parents, each one created noted in
    :data:`CREATED_FOLDERS` (for a refused command to take back).

    Raises:
        OSError: it cannot be created.
    """
    folder = Path(folder)
    missing = []
    f = folder
    while not f.exists() and f != f.parent:
        missing.append(f)
        f = f.parent
    folder.mkdir(parents=True, exist_ok=True)
    CREATED_FOLDERS.extend(reversed(missing))
    return folder


def forget_created_folders() -> None:
    """Start noting the folders created anew (a command's start, or its success)."""
    CREATED_FOLDERS.clear()


def take_back_created_folders() -> list[Path]:
    """Remove the folders noted in :data:`CREATED_FOLDERS` that are still empty, innermost
    first (a refused or interrupted command leaves no folder it created); returns those removed."""
    removed = []
    for folder in reversed(CREATED_FOLDERS):
        try:
            folder.rmdir()
        except OSError:  # not empty (or gone): it stays
            continue
        removed.append(folder)
    CREATED_FOLDERS.clear()
    return removed


def temporary_file(path: str | Path, suffix: str = ".tmp") -> Path:
    """A new hidden temporary file beside ``path``, named ``.{name}.{pid}-XXXXXXXX{suffix}``: the
    writer's process id in the name lets a later writer of ``path`` remove what a killed one left
    (:func:`remove_dead_writers_temporaries`). Temporaries of writers no longer running are removed first."""
    path = Path(path)
    remove_dead_writers_temporaries(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}-", suffix=suffix)
    os.close(fd)
    return Path(tmp)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process, or signals not allowed: it runs
        return True
    return True


def remove_dead_writers_temporaries(path: str | Path) -> list[Path]:
    """Remove the hidden temporaries of ``path`` (:func:`temporary_file`'s ``.{name}.{pid}-*.tmp``
    and ``.bak``) whose writer is no longer running (a killed command's); those of a running
    writer stay. Returns those removed."""
    path = Path(path)
    pattern = re.compile(rf"\.{re.escape(path.name)}\.(\d+)-[^.]*\.(tmp|bak)")
    removed = []
    try:
        entries = list(path.parent.glob(f".{glob.escape(path.name)}.*"))
    except OSError:
        return removed
    for entry in entries:
        found = pattern.fullmatch(entry.name)
        if found is None or int(found.group(1)) == os.getpid() or _running(int(found.group(1))):
            continue
        try:
            entry.unlink()
        except OSError:
            continue
        removed.append(entry)
    return removed



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
    make_folder(path.parent)
    tmp = temporary_file(path)
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


def read_text_file(path: str | Path, what: str, error: type[Exception] = ValueError) -> str:
    """The text of ``path`` (UTF-8, a byte-order mark accepted), or a one-line ``error`` naming it
    (``what`` says what the file should be)."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{path}: is a folder, not a {what}")
    if not path.exists():
        raise error(f"{path}: {what} not found")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise error(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    if b"\0" in data:
        raise error(f"{path}: not a text file (it holds NUL bytes): expected a {what}")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text (byte {exc.start}): expected a {what}") from None


def read_json_file(path: str | Path, what: str, error: type[Exception] = ValueError):
    """The JSON value of ``path`` (:func:`read_text_file`), or a one-line ``error`` naming the file
    and the line where it is not JSON."""
    text = read_text_file(path, what, error)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg}): expected a {what}") from None
