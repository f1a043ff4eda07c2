"""Import a lab's export as a recording (:func:`run_convert`; the command
``python -m pipeline.convert LAB.csv [LAB2.csv ...] --map MAP.toml --out NAME``).

The mapping file (TOML, :mod:`pipeline.formats.lab_export`, ``docs/importer.md``) says which lab
column is which joint and pose coordinate and in which units and conventions; each input file
becomes one session of the recording. Written: ``NAME.csv`` and ``NAME.json`` (the recording
format, :mod:`pipeline.formats.recording`), both or neither, never over an existing file unless
``overwrite``; the outputs are checked before any file is read. The converted data are checked
on evidence against the nominal machine (:func:`pipeline.formats.lab_checks`): a map key the
data prove wrong (another unit, the quaternion's scalar at the other end...) is refused by name.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pipeline.formats import (Recording, ResultSet, convert_lab_files, lab_checks, read_map, read_recording,
                              sidecar_path, write_recording)

__all__ = ["ConvertSettings", "ConvertResult", "run_convert", "output_paths"]


@dataclass(frozen=True, kw_only=True)
class ConvertSettings:
    """What :func:`run_convert` does (``python -m pipeline.convert --help`` describes each field).

    Attributes:
        files: the lab's files, one session each, in order.
        map: the mapping file (TOML).
        out: the recording's name: ``NAME`` or ``NAME.csv`` (its sidecar ``NAME.json`` beside it).
        overwrite: allow replacing an existing recording.
    """

    files: tuple[str, ...]
    map: str
    out: str
    overwrite: bool = False


@dataclass(frozen=True, eq=False)
class ConvertResult:
    """The recording written and where.

    Attributes:
        csv_path, json_path: the files written.
        recording: the recording, as read back from them.
        sessions: per session (in order) ``{"session", "file", "data_rows", "kept_rows"}``.
        warnings: what the checks on evidence suspect of the map (:func:`pipeline.formats.lab_checks`),
            one line each.
    """

    csv_path: Path
    json_path: Path
    recording: Recording
    sessions: tuple[dict, ...]
    warnings: tuple[str, ...] = ()


def output_paths(out: str | Path) -> tuple[Path, Path]:
    """``(NAME.csv, NAME.json)`` of ``--out NAME`` (or ``NAME.csv``)."""
    out = Path(out)
    csv_path = out if out.suffix.lower() == ".csv" else out.with_name(out.name + ".csv")
    return csv_path, sidecar_path(csv_path)


def run_convert(settings: ConvertSettings) -> ConvertResult:
    """Convert ``settings.files`` through ``settings.map`` into the recording ``settings.out``.

    Raises:
        LabExportError: a bad map or lab file (one line naming the file and the key, or the row
            and column), or a map key the converted data prove wrong (:func:`pipeline.formats.lab_checks`).
        FileExistsError, OutputError: the outputs cannot be written (checked before any work).
    """
    csv_path, json_path = output_paths(settings.out)
    for f in settings.files:
        if Path(f).resolve() in (csv_path.resolve(), json_path.resolve()):
            raise ValueError(f"--out {settings.out}: would write over the lab file {f}")
    with ResultSet({"csv": csv_path, "json": json_path}, overwrite=settings.overwrite,
                   flags={"csv": "--out", "json": "--out"}, create_folders=True):
        pass
    lab_map = read_map(settings.map)
    rec = convert_lab_files(lab_map, settings.files)
    warnings = lab_checks(lab_map, settings.files, rec)  # refuses a map key the data prove wrong
    write_recording(csv_path, rec, overwrite=settings.overwrite)
    back = read_recording(csv_path)
    return ConvertResult(csv_path=csv_path, json_path=json_path, recording=back,
                         sessions=tuple(back.meta["imported"]["files"]), warnings=tuple(warnings))
