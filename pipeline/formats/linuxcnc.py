"""LinuxCNC's files: a HAL file of kinematics parameters, an INI fragment, one compensation file
per joint, and the export's record (the mathematics: :mod:`calib.linuxcnc`).

Compensation files follow what LinuxCNC reads (``usrmotLoadComp``, ``motion/command.c``): one
line per entry, three numbers ``nominal actual_up actual_down`` (type 0), nominals strictly
increasing, at most 256 lines, and nothing else: the reader stops silently at the first line that
is not three numbers, so the files have no header and no comment. Numbers are written with
Python's shortest round-trip form (``repr``), which ``sscanf("%lf")`` reads back exactly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.linuxcnc import COMP_TABLE_SIZE, CompTable

from .outputs import ResultSet

__all__ = ["HAL_NAME", "INI_NAME", "NOTES_NAME", "RECORD_NAME", "comp_file_name", "genhex_hal_text",
           "rotarydelta_hal_text", "kins_ini_text",
           "comp_text", "check_export_folder", "write_export_folder", "AXES"]

#: The files of an export folder.
HAL_NAME, INI_NAME, NOTES_NAME, RECORD_NAME = "calibration.hal", "calibration.ini", "NOTES.md", "export.json"
#: The coordinates of a HAL ``x|y|z`` parameter triple.
AXES = ("x", "y", "z")


def comp_file_name(joint: int) -> str:
    """The compensation file of (0-based) ``joint``."""
    return f"joint{joint}.comp"


def _number(v: float) -> str:
    return repr(float(v))


def genhex_hal_text(base: np.ndarray, platform: np.ndarray, source: str) -> str:
    """``setp genhexkins.base.N.x|y|z`` and ``setp genhexkins.platform.N.x|y|z`` lines (N = 0..5,
    mm) of the base joints (6, 3) (base frame) and platform joints (6, 3) (platform frame)."""
    lines = [f"# genhexkins parameters of the identified hexapod ({source}).",
             "# Base joints in the base frame (LinuxCNC's world), platform joints in the platform frame, mm.",
             "# The legs' length offsets are in the joints' compensation files (see NOTES.md)."]
    for what, points in (("base", base), ("platform", platform)):
        for n, p in enumerate(points):
            lines += [f"setp genhexkins.{what}.{n}.{a} {_number(v)}" for a, v in zip(AXES, p)]
    return "\n".join(lines) + "\n"


def rotarydelta_hal_text(values: dict, source: str, frame: str) -> str:
    """``setp rotarydeltakins.<name> value`` lines of ``values`` (``{pin name: mm}``, the four
    lengths of :data:`calib.linuxcnc.ROTARYDELTA_PARAMETERS`); ``frame`` says where LinuxCNC's world
    lies (one comment line)."""
    lines = [f"# rotarydeltakins parameters fitted to the identified Delta ({source}), mm.",
             f"# {frame}",
             "# The joints' angle offsets are in the joints' compensation files; the projection's residual in NOTES.md."]
    lines += [f"setp rotarydeltakins.{name} {_number(v)}" for name, v in values.items()]
    return "\n".join(lines) + "\n"


def kins_ini_text(kinematics: str, joint_type: str, tables: list[CompTable], source: str, joint_word: str,
                  chains=None) -> str:
    """The INI fragment: ``[KINS]`` and one ``[JOINT_N]`` per joint naming its compensation file;
    ``chains[N]``: the calibration's chain (0-based) joint N drives (default N)."""
    lines = [f"# LinuxCNC INI fragment of the calibration {source}: merge these keys into the machine's INI.",
             "# COMP_FILE is opened as written: relative to the folder LinuxCNC runs in (the INI's), or give a full "
             "path.", "", "[KINS]", f"KINEMATICS = {kinematics}", f"JOINTS = {len(tables)}"]
    for t in tables:
        chain = t.joint if chains is None else int(chains[t.joint])
        lines += ["", f"[JOINT_{t.joint}]", f"# {joint_word} {chain + 1} of the calibration", f"TYPE = {joint_type}",
                  f"COMP_FILE = {comp_file_name(t.joint)}", "COMP_FILE_TYPE = 0"]
    return "\n".join(lines) + "\n"


def comp_text(table: CompTable) -> str:
    """A type-0 compensation file: ``nominal actual_up actual_down`` lines, nothing else."""
    if not 1 <= len(table.nominal) <= COMP_TABLE_SIZE or np.any(np.diff(table.nominal) <= 0):
        raise ValueError(f"joint {table.joint}: a compensation table needs 1..{COMP_TABLE_SIZE} strictly increasing "
                         "nominals")
    return "".join(f"{_number(n)} {_number(u)} {_number(d)}\n" for n, u, d in zip(table.nominal, table.up, table.down))


def _folder_set(out: Path, names, overwrite: bool) -> ResultSet:
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: is a file, not a folder")
    return ResultSet({name: out / name for name in names}, overwrite=overwrite, flags={name: "--out" for name in names},
                     create_folders=True)


def check_export_folder(out: Path, names, *, overwrite: bool = False) -> None:
    """Refuse, before any work, an export into ``out`` whose files ``names`` exist (unless
    ``overwrite``) or cannot be written."""
    with _folder_set(out, names, overwrite):
        pass


def write_export_folder(out: Path, texts: dict, *, overwrite: bool = False) -> dict:
    """Write ``texts`` (``{file name: text}``) into the folder ``out`` (created if missing), all
    together or none (:class:`pipeline.formats.ResultSet`); an existing file is refused unless
    ``overwrite``. Returns ``{file name: path}``."""
    with _folder_set(out, texts, overwrite) as files:
        for name, text in texts.items():
            files.temp(name).write_text(text)
        files.publish()
        return dict(files.paths)
