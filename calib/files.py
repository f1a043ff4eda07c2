"""Files at calib's edge: atomic writing and reading text and JSON with one-line errors.

The calibration file (:mod:`calib.calibration`) is read and written here; ``pipeline.formats``
writes every other output with the same helpers (:mod:`pipeline.formats.outputs`). Every file is
written to a temporary file beside its destination and moved into place when complete; an
existing file is never replaced unless asked to (``--overwrite``).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

__all__ = ["publish", "writing", "atomic_write", "read_text_file", "read_json_file"]


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
