"""Klipper's printer.cfg read into typed objects: a linear or rotary Delta's geometry and step
sizes, and the probe data of its ``[delta_calibrate]`` block (docs/klipper.md).

The syntax is Klipper's (its klippy/configfile.py): ``[section]`` headers, ``key: value`` or
``key = value`` (keys case-insensitive), comments from ``#`` to the end of a line and ``;`` at the
start of a line or after a blank, indented lines continuing the value above, ``[include FILE]``
(a glob relative to the including file), sections and keys given again overriding what came before,
and the SAVE_CONFIG block (``#*# <---- SAVE_CONFIG ---->``, every line after it prefixed ``#*# ``)
read after the rest, so that it overrides it. Lines prefixed ``#*# `` in a file without the header
(a block pasted on its own) are read as if it were there.

The machine *as built* (:attr:`KlipperConfig.built`, :attr:`KlipperPrinter.built`): the sections
above the block alone, as the owner wrote them, which SAVE_CONFIG overrides, and where it commented
a key out (Klipper's SAVE_CONFIG puts ``#`` before a key of the main config that its block now
sets, ``#delta_radius: 140``) the value so commented; Klipper's defaults where the owner wrote
none (stepper_b's ``arm_length`` is stepper_a's). It is the build before calibration, a prior's
centre, where the block holds a fit's; where the main sections cannot be read alone (the owner's
values are all in the block), the machine as Klipper runs it.

Units: lengths in mm; the towers' angles, which Klipper writes in degrees, are held in radians;
a rotary Delta's step size in radians. Stable positions (the steps counted from each tower's
endstop) are held as Klipper writes them, in steps.
"""

from __future__ import annotations

import glob
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.files import read_text_file

__all__ = ["KlipperError", "KlipperConfig", "KlipperDelta", "KlipperRotaryDelta", "ProbeData", "KlipperPrinter",
           "read_klipper_config", "parse_klipper_text", "read_klipper_printer", "klipper_printer",
           "SAVE_CONFIG_HEADER", "SAVE_CONFIG_PREFIX", "STEPPERS", "LINEAR_ANGLES_DEG", "ROTARY_ANGLES_DEG",
           "KINEMATICS", "CALIBRATE_SECTION", "save_config_block"]

#: The line that opens Klipper's SAVE_CONFIG block (any number of dashes is accepted).
SAVE_CONFIG_HEADER = "#*# <---------------------- SAVE_CONFIG ---------------------->"
#: The prefix of every line of the SAVE_CONFIG block.
SAVE_CONFIG_PREFIX = "#*# "
#: The line Klipper writes below the header (read as a comment).
SAVE_CONFIG_NOTICE = "DO NOT EDIT THIS BLOCK OR BELOW"
HEADER_PATTERN = re.compile(r"#\*#\s*<-+\s*SAVE_CONFIG\s*-+>\s*$")
INCLUDE_PATTERN = re.compile(r"\[\s*include\s+(.+?)\s*\]\s*$")
#: The three towers' stepper sections, in Klipper's order a, b, c.
STEPPERS = ("stepper_a", "stepper_b", "stepper_c")
#: The towers' default angles, degrees: linear Delta and rotary Delta.
LINEAR_ANGLES_DEG = (210.0, 330.0, 90.0)
ROTARY_ANGLES_DEG = (30.0, 150.0, 270.0)
#: ``[printer] kinematics`` values read.
KINEMATICS = ("delta", "rotary_delta")
CALIBRATE_SECTION = "delta_calibrate"
DEFAULT_FULL_STEPS = 200
#: Klipper refuses a ``full_steps_per_rotation`` that is not a multiple of this.
FULL_STEPS_MULTIPLE = 4
#: An index of a ``[delta_calibrate]`` series as Klipper writes it (``%d``: no leading zero).
INDEX = r"(0|[1-9][0-9]*)"
REQUIRED = object()


def save_config_block(lines: list) -> str:
    """The SAVE_CONFIG block of the config ``lines`` as Klipper writes it: the header, its notice
    and every line prefixed (trailing blanks removed)."""
    block = [f"{SAVE_CONFIG_NOTICE}. The contents are auto-generated.", ""] + list(lines)
    return "\n".join([SAVE_CONFIG_HEADER] + [f"{SAVE_CONFIG_PREFIX}{line}".rstrip() for line in block]) + "\n"


class KlipperError(ValueError):
    """A Klipper config that cannot be read; the message names the file, line, section and key."""


@dataclass(frozen=True)
class Entry:
    """A key's value and where it was read (``file: line N``)."""

    value: str
    where: str


@dataclass(frozen=True, eq=False)
class KlipperConfig:
    """The sections of a config after includes and the SAVE_CONFIG block: ``{section: {key: Entry}}``
    (keys lower case); ``built``: the config as built (module docstring), None where it is itself."""

    path: Path
    sections: dict
    built: "KlipperConfig | None" = None

    def entry(self, section: str, key: str) -> Entry | None:
        return self.sections.get(section, {}).get(key)

    def value(self, section: str, key: str, default=REQUIRED, hint: str = "") -> str:
        """The text of ``[section] key``; ``default`` when absent (a one-line error when required)."""
        e = self.entry(section, key)
        if e is not None:
            return e.value
        if default is REQUIRED:
            if section not in self.sections:
                raise KlipperError(f"{self.path}: no [{section}] section{hint}")
            raise KlipperError(f"{self.path}: [{section}] {key} is missing{hint}")
        return default

    def refuse(self, section: str, key: str, what: str):
        """A one-line error about ``[section] key`` naming where it was read."""
        e = self.entry(section, key)
        where = e.where if e is not None else str(self.path)
        raise KlipperError(f"{where}: [{section}] {key}: {what}")

    def number(self, section: str, key: str, default=REQUIRED, above: float | None = None, hint: str = "",
               above_name: str = "") -> float:
        """``[section] key`` as a finite number (greater than ``above``, called ``above_name``, where
        given)."""
        text = self.value(section, key, default, hint)
        if text is default:
            return default
        v = finite_float(text)
        if v is None:
            self.refuse(section, key, f"{text!r} is not a number")
        if above is not None and not v > above:
            self.refuse(section, key, f"{text} must be greater than {above_name or format(above, 'g')}")
        return v

    def integer(self, section: str, key: str, default=REQUIRED) -> int:
        """``[section] key`` as a whole number of at least 1."""
        text = self.value(section, key, default)
        if text is default:
            return default
        if not re.fullmatch(r"\s*\+?[0-9]+\s*", text) or int(text) < 1:
            self.refuse(section, key, f"{text!r} is not a whole number of at least 1")
        return int(text)

    def stable_position(self, section: str, key: str) -> np.ndarray:
        """``[section] key`` as a stable position ``a,b,c`` (steps from each tower's endstop)."""
        text = self.value(section, key)
        parts = [finite_float(p) for p in text.split(",")]
        if len(parts) != 3 or any(p is None for p in parts):
            self.refuse(section, key, f"{text!r} is not three numbers a,b,c (the steps counted from each tower's "
                                      "endstop)")
        return np.array(parts, dtype=float)


def finite_float(text: str) -> float | None:
    """``text`` as a finite float (Python's literal, no ``_`` separators), else None."""
    if "_" in text:
        return None
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def strip_comment(line: str) -> str:
    """``line`` without its comment (``#`` anywhere; ``;`` at the start or after a blank)."""
    line = line.split("#", 1)[0]
    if line.strip().startswith(";"):
        return ""
    m = re.search(r"\s;", line)
    return (line[:m.start()] if m else line).rstrip()


def unprefixed(line: str) -> str:
    """A SAVE_CONFIG block's line without its prefix (Klipper's notice below the header: empty)."""
    line = line[len(SAVE_CONFIG_PREFIX):]
    return "" if line.startswith(SAVE_CONFIG_NOTICE) else line


def split_save_config(text: str, path: Path) -> tuple[list, list]:
    """The numbered lines ``(n, line)`` above the SAVE_CONFIG header and those of the block (prefix
    removed)."""
    lines = text.replace("\r\n", "\n").split("\n")
    header = next((n for n, line in enumerate(lines) if HEADER_PATTERN.match(line)), None)
    if header is None:
        return [(n + 1, unprefixed(line) if line.startswith(SAVE_CONFIG_PREFIX) else line)
                for n, line in enumerate(lines)], []
    block = []
    for n, line in enumerate(lines[:header]):
        if line.startswith(SAVE_CONFIG_PREFIX):
            raise KlipperError(f"{path}: line {n + 1}: a {SAVE_CONFIG_PREFIX.strip()!r} line above the SAVE_CONFIG "
                               f"header (line {header + 1}): the block is corrupted; Klipper would not read it")
    for n, line in enumerate(lines[header + 1:], start=header + 2):
        if line.strip() and not (line.rstrip() == SAVE_CONFIG_PREFIX.strip() or line.startswith(SAVE_CONFIG_PREFIX)):
            raise KlipperError(f"{path}: line {n}: not prefixed {SAVE_CONFIG_PREFIX!r} below the SAVE_CONFIG header "
                               f"(line {header + 1}): edited after Klipper wrote it; Klipper would not read the block")
        block.append((n, unprefixed(line)))
    return [(n + 1, line) for n, line in enumerate(lines[:header])], block


def resolve_includes(numbered: list, path: Path, visited: frozenset) -> list:
    """``(where, line)`` pairs with every ``[include FILE]`` replaced by the lines of its files."""
    out = []
    for n, line in numbered:
        m = INCLUDE_PATTERN.match(strip_comment(line).strip())
        if not m:
            out.append((f"{path}: line {n}", line))
            continue
        spec = str(path.parent / m.group(1))
        names = sorted(glob.glob(spec))
        if not names and not glob.has_magic(spec):
            raise KlipperError(f"{path}: line {n}: [include {m.group(1)}]: {spec} does not exist")
        for name in names:
            included = Path(name)
            if included.resolve() in visited:
                raise KlipperError(f"{path}: line {n}: [include {m.group(1)}]: {included} includes itself")
            text = read_text_file(included, "Klipper config file", KlipperError)
            lines = list(enumerate(text.replace("\r\n", "\n").split("\n"), start=1))
            out += resolve_includes(lines, included, visited | {included.resolve()})
    return out


def parse_lines(lines: list) -> dict:
    """``{section: {key: Entry}}`` of ``(where, line)`` pairs, later keys overriding earlier ones."""
    sections: dict = {}
    section = key = None
    for where, raw in lines:
        line = strip_comment(raw)
        if not line.strip():
            continue
        if line[0].isspace() and key is not None:
            e = sections[section][key]
            sections[section][key] = Entry(f"{e.value}\n{line.strip()}" if e.value else line.strip(), e.where)
            continue
        text = line.strip()
        if text.startswith("["):
            if not text.endswith("]") or not text[1:-1].strip():
                raise KlipperError(f"{where}: {text!r} is not a [section] header")
            section, key = text[1:-1].strip(), None
            sections.setdefault(section, {})
            continue
        m = re.match(r"([^:=]*?)\s*[:=]\s*(.*)$", text)
        if m is None or not m.group(1):
            raise KlipperError(f"{where}: {text!r} is neither a [section], a 'key: value' nor an indented "
                               "continuation of a value")
        if section is None:
            raise KlipperError(f"{where}: {m.group(1)!r} comes before any [section]")
        key = m.group(1).lower()
        sections[section][key] = Entry(m.group(2), where)
    return sections


#: A key of the main config that Klipper's SAVE_CONFIG commented out: ``#`` then ``key: value``.
COMMENTED_OUT = re.compile(r"#([A-Za-z0-9_]+\s*[:=].*)$")


def parse_klipper_text(text: str, path) -> KlipperConfig:
    """The config of ``text`` (read from ``path``: named in messages, includes relative to it)."""
    path = Path(path)
    regular, block = split_save_config(text, path)
    lines = resolve_includes(regular, path, frozenset({path.resolve()}))
    saved = [(f"{path}: line {n} (SAVE_CONFIG)", line) for n, line in block]
    sections = parse_lines(lines + saved)
    built = parse_lines(restored_lines(lines, parse_lines(saved), parse_lines(lines))) if block else None
    return KlipperConfig(path, sections, None if built is None else KlipperConfig(path, built))


def restored_lines(lines: list, saved: dict, main: dict) -> list:
    """``lines`` of the main config (its sections ``main``) with the keys Klipper's SAVE_CONFIG
    commented out read again: ``#key: value`` in a section where its block ``saved`` sets the key
    and the main config does not, the one such line of that key in that section (several: which
    was the owner's is not known, none is read)."""
    found, section = [], None
    for where, raw in lines:
        text = strip_comment(raw).strip()
        if text.startswith("[") and text.endswith("]"):
            section = text[1:-1].strip()
        m = COMMENTED_OUT.match(raw)
        key = re.split(r"\s*[:=]", m.group(1))[0].lower() if m else None
        restore = m and key in saved.get(section, {}) and key not in main.get(section, {})
        found.append((section, key, m.group(1)) if restore else None)
    counts: dict = {}
    for f in filter(None, found):
        counts[f[:2]] = counts.get(f[:2], 0) + 1
    return [(where, f[2] if f and counts[f[:2]] == 1 else raw) for (where, raw), f in zip(lines, found)]


def read_klipper_config(path) -> KlipperConfig:
    """The config of the file ``path`` (see the module docstring)."""
    return parse_klipper_text(read_text_file(path, "Klipper config file", KlipperError), path)


@dataclass(frozen=True, eq=False)
class KlipperDelta:
    """A linear Delta as Klipper holds it (its klippy/kinematics/delta.py).

    Attributes:
        radius_mm: ``delta_radius``, the towers' distance from the centre (minus the effector's).
        angles_rad: (3,) the towers' angles about z (``angle``), rad.
        arm_lengths_mm: (3,) ``arm_length``, towers a, b, c.
        endstops_mm: (3,) ``position_endstop``.
        step_distances_mm: (3,) carriage travel of one (micro)step.
        print_radius_mm: ``print_radius`` (default ``delta_radius``).
    """

    radius_mm: float
    angles_rad: np.ndarray
    arm_lengths_mm: np.ndarray
    endstops_mm: np.ndarray
    step_distances_mm: np.ndarray
    print_radius_mm: float


@dataclass(frozen=True, eq=False)
class KlipperRotaryDelta:
    """A rotary Delta as Klipper holds it (its klippy/kinematics/rotary_delta.py).

    Attributes:
        shoulder_radius_mm, shoulder_height_mm: the shoulder joints' distance from the centre and
            height.
        upper_arm_lengths_mm, lower_arm_lengths_mm: (3,) per stepper.
        angles_rad: (3,) the shoulders' angles about z, rad.
        endstops_mm: (3,) ``position_endstop``: the height of the effector at the centre where the arm
            meets its endstop.
        step_angles_rad: (3,) the arm's turn of one (micro)step.
    """

    shoulder_radius_mm: float
    shoulder_height_mm: float
    upper_arm_lengths_mm: np.ndarray
    lower_arm_lengths_mm: np.ndarray
    angles_rad: np.ndarray
    endstops_mm: np.ndarray
    step_angles_rad: np.ndarray


@dataclass(frozen=True, eq=False)
class ProbeData:
    """The measurements of a ``[delta_calibrate]`` block (its klippy/extras/delta_calibrate.py).

    Attributes:
        touch_steps: (N, 3) stable positions of the probe's touches (``heightN_pos``), steps.
        touch_z_mm: (N,) the z of the tool point at each touch (``heightN``: the probe's z offset).
        manual_steps: (M, 3) stable positions of the manual heights (``manual_heightN_pos``).
        manual_z_mm: (M,) their heights (``manual_heightN``).
        distance_mm: (K,) distances measured between two positions (``distanceN``).
        distance_steps: (K, 2, 3) their two stable positions (``distanceN_pos1``, ``distanceN_pos2``).
        radius_mm: the probing radius (``radius``), None when the block does not say.
    """

    touch_steps: np.ndarray
    touch_z_mm: np.ndarray
    manual_steps: np.ndarray
    manual_z_mm: np.ndarray
    distance_mm: np.ndarray
    distance_steps: np.ndarray
    radius_mm: float | None


@dataclass(frozen=True, eq=False)
class KlipperPrinter:
    """What a printer.cfg says of a Delta: ``kinematics`` (one of :data:`KINEMATICS`), the machine
    (as Klipper runs it: the SAVE_CONFIG block's values win), the machine as built (the module
    docstring; the machine itself without a block), and the probe data (None without a
    ``[delta_calibrate]`` section)."""

    path: Path
    kinematics: str
    machine: KlipperDelta | KlipperRotaryDelta
    probe: ProbeData | None
    built: KlipperDelta | KlipperRotaryDelta


def step_size(cfg: KlipperConfig, section: str, in_radians: bool) -> float:
    """One (micro)step: ``rotation_distance`` (2 pi for a rotary arm) / (``full_steps_per_rotation``
    x ``microsteps`` x ``gear_ratio``) (Klipper's klippy/stepper.py)."""
    if in_radians:
        turn = 2.0 * math.pi
        cfg.value(section, "gear_ratio", hint=" (a rotary Delta's arm needs it: the motor's turns per arm turn)")
    elif cfg.entry(section, "rotation_distance") is None and cfg.entry(section, "step_distance") is not None:
        cfg.refuse(section, "step_distance", "Klipper's old key: give rotation_distance = step_distance x "
                                             "full_steps_per_rotation x microsteps")
    else:
        turn = cfg.number(section, "rotation_distance", above=0.0)
    microsteps = cfg.integer(section, "microsteps")
    full_steps = cfg.integer(section, "full_steps_per_rotation", DEFAULT_FULL_STEPS)
    if full_steps % FULL_STEPS_MULTIPLE:
        cfg.refuse(section, "full_steps_per_rotation", f"{full_steps} is not a multiple of {FULL_STEPS_MULTIPLE}")
    return turn / (full_steps * microsteps * gear_ratio(cfg, section))


def gear_ratio(cfg: KlipperConfig, section: str) -> float:
    """``gear_ratio`` ``a:b`` pairs, separated by commas, multiplied (a / b each; default 1)."""
    text = cfg.value(section, "gear_ratio", "")
    ratio = 1.0
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        pair = [finite_float(v) for v in part.split(":")]
        if len(pair) != 2 or any(v is None or v <= 0 for v in pair):
            cfg.refuse(section, "gear_ratio", f"{part!r} is not a pair of positive numbers a:b "
                                              "(pairs separated by commas: '80:16, 3:1')")
        ratio *= pair[0] / pair[1]
    return ratio


def per_stepper(cfg: KlipperConfig, key: str, defaults, above=None, hint: str = "", above_name: str = "") -> np.ndarray:
    """``key`` of each tower's stepper section; ``defaults``: one per tower, or None: stepper_a's
    (required)."""
    if defaults is None:
        first = cfg.number(STEPPERS[0], key, above=above, hint=hint, above_name=above_name)
        defaults = (first,) * len(STEPPERS)
    return np.array([cfg.number(s, key, d, above=above, above_name=above_name) for s, d in zip(STEPPERS, defaults)])


def linear_delta(cfg: KlipperConfig) -> KlipperDelta:
    """The linear Delta of ``cfg`` (``[printer] kinematics: delta``)."""
    radius = cfg.number("printer", "delta_radius", above=0.0)
    arms = per_stepper(cfg, "arm_length", None, above=radius, above_name=f"delta_radius {radius:g} (the arms reach "
                       "across it)", hint=" (the towers' arm length; stepper_b's and stepper_c's default to it)")
    return KlipperDelta(
        radius_mm=radius, angles_rad=np.radians(per_stepper(cfg, "angle", LINEAR_ANGLES_DEG)), arm_lengths_mm=arms,
        endstops_mm=per_stepper(cfg, "position_endstop", None,
                                hint=" (the tower's endstop height; stepper_b's and stepper_c's default to it)"),
        step_distances_mm=np.array([step_size(cfg, s, False) for s in STEPPERS]),
        print_radius_mm=cfg.number("printer", "print_radius", radius, above=0.0))


def rotary_delta(cfg: KlipperConfig) -> KlipperRotaryDelta:
    """The rotary Delta of ``cfg`` (``[printer] kinematics: rotary_delta``)."""
    hint = " (stepper_b's and stepper_c's default to stepper_a's)"
    return KlipperRotaryDelta(
        shoulder_radius_mm=cfg.number("printer", "shoulder_radius", above=0.0),
        shoulder_height_mm=cfg.number("printer", "shoulder_height", above=0.0),
        upper_arm_lengths_mm=per_stepper(cfg, "upper_arm_length", None, above=0.0, hint=hint),
        lower_arm_lengths_mm=per_stepper(cfg, "lower_arm_length", None, above=0.0, hint=hint),
        angles_rad=np.radians(per_stepper(cfg, "angle", ROTARY_ANGLES_DEG)),
        endstops_mm=per_stepper(cfg, "position_endstop", None, hint=hint),
        step_angles_rad=np.array([step_size(cfg, s, True) for s in STEPPERS]))


def indices(cfg: KlipperConfig, stem: str, suffixes: tuple) -> list[int]:
    """The indices N of ``stemN`` in ``[delta_calibrate]``: 0, 1, 2, ... without a gap, each with
    its ``stemN_<suffix>`` keys (Klipper stops at the first missing N and ignores the rest)."""
    keys = cfg.sections[CALIBRATE_SECTION]
    found = sorted(int(m.group(1)) for k in keys if (m := re.fullmatch(stem + INDEX, k)))
    for expected, n in enumerate(found):
        if n != expected:
            cfg.refuse(CALIBRATE_SECTION, f"{stem}{n}", f"{stem}{expected} is missing: Klipper reads {stem}0, "
                                                         f"{stem}1, ... and stops at the first one missing")
    for k in keys:
        m = re.fullmatch(stem + INDEX + "_(.+)", k)
        if m and int(m.group(1)) not in found and m.group(2) in suffixes:
            cfg.refuse(CALIBRATE_SECTION, k, f"there is no {stem}{m.group(1)} for it")
    for n in found:
        for s in suffixes:
            cfg.value(CALIBRATE_SECTION, f"{stem}{n}_{s}", hint=f" ({stem}{n} has no stable position)")
    return found


def height_series(cfg: KlipperConfig, stem: str) -> tuple[np.ndarray, np.ndarray]:
    """Stable positions (N, 3) and heights (N,) of ``stemN`` / ``stemN_pos``."""
    found = indices(cfg, stem, ("pos",))
    steps = np.array([cfg.stable_position(CALIBRATE_SECTION, f"{stem}{n}_pos") for n in found]).reshape(-1, 3)
    return steps, np.array([cfg.number(CALIBRATE_SECTION, f"{stem}{n}") for n in found])


def probe_data(cfg: KlipperConfig) -> ProbeData | None:
    """The ``[delta_calibrate]`` block of ``cfg``, None without one."""
    if CALIBRATE_SECTION not in cfg.sections:
        return None
    touch_steps, touch_z = height_series(cfg, "height")
    manual_steps, manual_z = height_series(cfg, "manual_height")
    found = indices(cfg, "distance", ("pos1", "pos2"))
    pairs = [[cfg.stable_position(CALIBRATE_SECTION, f"distance{n}_{s}") for s in ("pos1", "pos2")] for n in found]
    return ProbeData(touch_steps=touch_steps, touch_z_mm=touch_z, manual_steps=manual_steps, manual_z_mm=manual_z,
                     distance_mm=np.array([cfg.number(CALIBRATE_SECTION, f"distance{n}", above=0.0) for n in found]),
                     distance_steps=np.array(pairs, dtype=float).reshape(-1, 2, 3),
                     radius_mm=cfg.number(CALIBRATE_SECTION, "radius", None, above=0.0))


def klipper_printer(cfg: KlipperConfig) -> KlipperPrinter:
    """The Delta of a read config, refused by name when it is not one."""
    kinematics = cfg.value("printer", "kinematics", hint=" (a Klipper printer config names its kinematics)").strip()
    if kinematics not in KINEMATICS:
        cfg.refuse("printer", "kinematics", f"{kinematics!r} is not a Delta: read are {', '.join(KINEMATICS)}")
    for s in STEPPERS:
        if s not in cfg.sections:
            raise KlipperError(f"{cfg.path}: no [{s}] section: a Delta has [{'], ['.join(STEPPERS)}]")
    read = linear_delta if kinematics == "delta" else rotary_delta
    machine = built = read(cfg)
    if cfg.built is not None:
        try:
            built = read(cfg.built)
        except KlipperError:  # the owner's values are in the block alone: none before it to read
            pass
    return KlipperPrinter(path=cfg.path, kinematics=kinematics, machine=machine, probe=probe_data(cfg), built=built)


def read_klipper_printer(path) -> KlipperPrinter:
    """The Delta and probe data of the printer.cfg ``path``.

    Raises:
        KlipperError: one line naming the file, line, section and key, and what is wrong.
    """
    return klipper_printer(read_klipper_config(path))
