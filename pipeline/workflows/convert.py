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

from pipeline.formats import (Recording, ResultSet, import_lab_files, read_map, read_recording, sidecar_path,
                              sidecar_text)
from pipeline.formats.lab_checks import lab_checks  # the function: the package's name is also the module's

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
        robot: the robot's name.
        rows: the rows written.
        extras: the extra channels kept.
        sessions: per session (in order) ``{"session", "file", "data_rows", "kept_rows",
            "validation_rows", "frame"}`` (``frame``: its instrument frame as declared).
        checked_rows: the rows the checks on evidence judged the map on (all ``rows``, or a seeded
            subsample of them).
        check_seed: that subsample's seed.
        warnings: what the checks on evidence suspect of the map (:func:`pipeline.formats.lab_checks`),
            one line each.
    """

    csv_path: Path
    json_path: Path
    robot: str
    rows: int
    extras: tuple[str, ...]
    sessions: tuple[dict, ...]
    checked_rows: int
    check_seed: int
    warnings: tuple[str, ...] = ()

    @property
    def recording(self) -> Recording:
        """The recording, read back from the files (all of it in memory: for small ones)."""
        return read_recording(self.csv_path)


def output_paths(out: str | Path) -> tuple[Path, Path]:
    """``(NAME.csv, NAME.json)`` of ``--out NAME`` (or ``NAME.csv``)."""
    out = Path(out)
    csv_path = out if out.suffix.lower() == ".csv" else out.with_name(out.name + ".csv")
    return csv_path, sidecar_path(csv_path)


def run_convert(settings: ConvertSettings) -> ConvertResult:
    """Convert ``settings.files`` through ``settings.map`` into the recording ``settings.out``,
    streaming: the CSV is written to a temporary file beside it as the lab's rows are converted,
    chunk by chunk; the sidecar when they all are; both moved into place once the map has passed
    the checks on evidence (nothing left on a refusal or an interruption).

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
                   flags={"csv": "--out", "json": "--out"}, create_folders=True) as out:
        lab_map = read_map(settings.map)
        with open(out.temp("csv"), "w", newline="") as csv_file:
            imported = import_lab_files(lab_map, settings.files, csv_file)
        warnings = lab_checks(lab_map, imported.sample)  # refuses a map key the data prove wrong
        out.temp("json").write_text(sidecar_text(lab_map.robot, lab_map.noise, imported.meta, imported.header,
                                                 imported.session_info))
        out.publish()
    measurement = imported.meta.get("measurement", {})
    sessions = tuple(dict(f, validation_rows=imported.validation_rows[f["session"]],
                          frame=imported.session_info[f["session"]].get("measurement", measurement).get("frame",
                                                                                                          "auto"))
                     for f in imported.meta["imported"]["files"])
    return ConvertResult(csv_path=csv_path, json_path=json_path, robot=lab_map.robot.name,
                         rows=sum(f["kept_rows"] for f in sessions), extras=tuple(lab_map.tables["extra"]),
                         sessions=sessions, checked_rows=len(imported.sample.recording.t_s),
                         check_seed=imported.sample.seed, warnings=tuple(warnings))
