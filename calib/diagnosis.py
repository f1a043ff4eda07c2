"""Why a recording does not fit its machine: a units, axis, sign or joint-direction mistake, gross
rows, a column never measured, or physics the model leaves out.

:func:`diagnose` judges the data as written first: the geometry (with an instrument frame where the
data need one, :func:`calib.measurement.identify_measured`, frame ``"auto"``) fitted to them,
chi-square of the whitened residuals against the declared noise. The data **fit** when the
chi-square is at most the chi-square(dof) quantile ``1 - FIT_ALPHA`` (:data:`FIT_ALPHA` = 0.001:
one honest file in a thousand is called a misfit; for 300 degrees of freedom the limit is 1.27
per degree of freedom). A fit is **plausible** when no free parameter moved more than
:data:`PLAUSIBLE_TOLERANCES` times its manufacturing tolerance (the robot's
``default_parameter_tolerance``, :class:`calib.prior.ParameterPrior`); a 6-RUS motor read backwards
is fitted to the noise by turning its axis by pi (600 tolerances), a capture body mounted 2
degrees off by turning the platform joints (50 tolerances on the hexapod, 20 on the 6-RUS).

A plausible fit is the verdict **nothing wrong** (``success``). Otherwise each conversion of
:func:`conversion_registry` (metres for mm, degrees for rad, two position axes swapped, a position
axis or an angle with its sign flipped, the angles in reversed order, another rotation convention,
the joints in metres or degrees, one joint read backwards) is applied to the file, and a
conversion is **named** only on evidence: the converted data fit plausibly, and the data as written
either do not fit (a chi-square per degree of freedom at least :data:`MIN_IMPROVEMENT` times the
converted one's) or fit only implausibly. Cost: a screen (every conversion fitted on a subset of
the rows, :data:`SCREEN_ROWS_FACTOR` times the fewest rows that identify the unknowns,
:data:`SCREEN_ITERATIONS` Gauss-Newton iterations from the nominal geometry), then the full fit
(Levenberg-Marquardt, :data:`FULL_ITERATIONS`) for the best :data:`SCREEN_KEEP` of those within
:data:`MIN_IMPROVEMENT` times the best screened chi-square per degree of freedom. Where several conversions fit (with a frame estimated every mirror image of a
translating platform's positions is another: x flipped, y flipped, x and y swapped), the one that
needs no instrument frame is named, then the one whose frame turns least (the others add a half turn
to it), then the smallest chi-square; the others are listed. The screen hands the full fit its
candidates in that order too: their screened chi-squares differ by the frame's degrees of freedom
alone, so the flipped axis itself would otherwise lose its place to a mirror image.

No conversion: a column holding one value on every row while the nominal model moves the
platform along it by more than :data:`CONSTANT_COLUMN_STDS` noise standard deviations is a column
**not measured**; then :func:`calib.robust.find_gross_rows` names **gross rows** when the others
fit; otherwise the model **does not fit**: an effect it leaves out (or noise declared too small).
A data set that fits as written but only implausibly, with no conversion that fits plausibly, is
still **nothing wrong**, with a note: the calibration then carries the offset in the geometry
(a capture body tilted on the platform is absorbed by the platform joints' coordinates, which then
describe the capture body's frame: predictions are right, the identified platform joints are
turned by the tilt).
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from .measurement import identify_measured
from .noise import SensorNoise, chi2_quantile
from .prior import ParameterPrior
from .robot import KinematicsError, Robot
from .rotation import euler_from_matrix, rotation_matrix

__all__ = ["Conversion", "conversion_registry", "FitFigures", "Diagnosis", "diagnose", "CAUSES", "FIT_ALPHA",
           "MIN_IMPROVEMENT", "PLAUSIBLE_TOLERANCES", "SCREEN_KEEP", "SCREEN_ROWS_FACTOR", "SCREEN_ITERATIONS",
           "FULL_ITERATIONS", "CONSTANT_COLUMN_STDS", "chi2_limit", "same_pose_rows", "motionless_rows",
           "SAME_POSE_STDS", "SAME_POSE_FRACTION", "TURN_RESOLUTION",
           "description_pattern", "ScalePattern", "PATTERN_FIT", "Comparison", "compare_readings"]

#: False-alarm probability of the fit test: data fit when chi-square <= the chi-square(dof)
#: ``1 - FIT_ALPHA`` quantile.
FIT_ALPHA = 1e-3
#: A conversion is named against data that do not fit only when it lowers the chi-square per
#: degree of freedom at least this many times.
MIN_IMPROVEMENT = 10.0
#: A fit is plausible when no free parameter moved more than this many tolerances.
PLAUSIBLE_TOLERANCES = 10.0
#: A parameter's movement counts for the plausibility only beyond this many of its standard
#: deviations in the fit (the rows place it there).
SIGNIFICANT = 3.0
#: The data as written are blamed on a movement only beyond this many of its standard deviations.
DECISIVE = 10.0
#: Conversions given the full fit after the screen.
SCREEN_KEEP = 3
#: The screen fits this many times the fewest rows that identify the unknowns (all rows if fewer).
SCREEN_ROWS_FACTOR = 3
#: Gauss-Newton iterations of a screening fit (from the nominal geometry, one gauge pass): enough
#: to bring data that fit to near their minimum, never enough to drag wrong data there.
SCREEN_ITERATIONS = 2
#: Above this many rows the diagnosis judges a seeded subsample of this many rows (its fits, the
#: conversions screened, its gross rows among them): the mistakes it names (a unit, a convention,
#: an unmeasured column) are properties of the file, shown by a few thousand rows as by all; the
#: run's own gross-row search still judges every row.
DIAGNOSIS_MAX_ROWS = 2000
#: Levenberg-Marquardt budget of a full fit, in Jacobians per unknown (``max_iter`` of
#: :func:`calib.engine.minimise`: ``max_iter * (unknowns + 1)`` evaluations; a clean file
#: converges within a tenth of it).
FULL_ITERATIONS = 2
#: A constant column is "not measured" when the nominal model spreads the platform along it by
#: more than this many noise standard deviations.
CONSTANT_COLUMN_STDS = 100.0

#: The verdicts: nothing wrong, a conversion, a column not measured, gross rows, the model misfits.
CAUSES = ("none", "conversion", "unmeasured column", "gross rows", "left-out physics")


def chi2_limit(dof: int, alpha: float = FIT_ALPHA) -> float:
    """The chi-square(dof) ``1 - alpha`` quantile (inf for dof <= 0: nothing can be judged)."""
    return chi2_quantile(1.0 - alpha, dof) if dof > 0 else float("inf")


# --------------------------------------------------------------------------- motion

#: Two rows are at the same pose when every joint reading differs by at most this many joint-noise
#: standard deviations ...
SAME_POSE_STDS = 5.0
#: ... or by this fraction of the joint's range (noise-free joints).
SAME_POSE_FRACTION = 1e-6


def same_pose_rows(robot: Robot, joints, joint_std: float = 0.0) -> np.ndarray:
    """0-based rows of the largest group of ``joints`` (N, C, joint unit) at one pose: readings
    on one cell of a grid :data:`SAME_POSE_STDS` times ``joint_std`` (the declared joint noise)
    wide, at least :data:`SAME_POSE_FRACTION` of each joint's range."""
    q = np.asarray(joints, dtype=float)
    if len(q) == 0:
        return np.zeros(0, dtype=int)
    limits = robot.joint_limits()
    cell = np.maximum(SAME_POSE_FRACTION * np.maximum(limits[:, 1] - limits[:, 0], 1e-12), SAME_POSE_STDS * joint_std)
    _, inverse, counts = np.unique(np.round(q / cell), axis=0, return_inverse=True, return_counts=True)
    return np.flatnonzero(inverse.ravel() == int(np.argmax(counts)))


def motionless_rows(robot: Robot, joints, joint_std: float = 0.0) -> int | None:
    """The number of rows of ``joints`` (N, C), N >= 2, where every row is at one pose
    (:func:`same_pose_rows`): rows that do not move the machine; None otherwise (worded by
    :func:`pipeline.report.verdict_words.no_motion_words`)."""
    n = len(joints)
    if n < 2 or len(same_pose_rows(robot, joints, joint_std)) < n:
        return None
    return n


# --------------------------------------------------------------------------- the description

#: The fitted errors of a group of length parameters are a scale of the description when the
#: scale explains them to this fraction of their norm (the rest's norm over theirs).
PATTERN_FIT = 0.2


def _group(name: str) -> str:
    """A parameter's group: the letters before its chain number (``B1.x`` -> ``B``, ``dl3`` -> ``dl``)."""
    head = re.match(r"[A-Za-z_]+?(?=\d)", name)
    return head.group(0) if head else name


@dataclass(frozen=True)
class ScalePattern:
    """A group of length parameters whose fitted errors are a scale of their nominal values
    (:func:`description_pattern`).

    Attributes:
        group: the letters the group's parameters share (``B``).
        names: its parameters.
        scale: the least-squares factor ``s`` of the errors on the nominal values.
        residual: the RMS of what the scale leaves of the errors, mm.
        largest_error: the largest error's magnitude, mm.
        largest: the largest error in tolerances.
    """

    group: str
    names: tuple
    scale: float
    residual: float
    largest_error: float
    largest: float
    unit: str = "mm"

    @property
    def factor(self) -> float:
        """The description over the fitted value: ``1 / (1 + scale)``."""
        return 1.0 / (1.0 + self.scale)

    def words(self) -> str:
        """The pattern in words (the diagnosis' message and the verdict's say it)."""
        return (f"the fitted errors of {self.names[0]} ... {self.names[-1]} ({len(self.names)} parameters, up to "
                f"{self.largest_error:.3g} mm) are {100 * self.scale:+.3g}% of their nominal values, to "
                f"{self.residual:.2g} mm RMS: the description's {self.group} coordinates are "
                f"{self.factor:.3g} times this machine's (a scale of the description)")


def description_pattern(robot: Robot, errors, tolerance, names=None) -> list[ScalePattern]:
    """Groups of length parameters whose fitted errors are a scale of their nominal values: the
    nominal geometry described is another machine's (or this one's scaled), not physics.

    A group (the parameters sharing the letters before the chain number: every base joint
    coordinate ``B1.x ... B6.z``) is named when the errors ``e`` (of ``names``, default the free
    ones) are the nominal values ``n`` times one factor ``s`` (least squares) to
    :data:`PATTERN_FIT` of their norm, some error is beyond :data:`PLAUSIBLE_TOLERANCES`
    tolerances, and the nominal values differ (a scale of equal values is a common offset).

    Args:
        errors: (P,) fitted errors from nominal, parameter units.
        tolerance: (P,) each parameter's tolerance (one standard deviation).

    Returns:
        a :class:`ScalePattern` per group named, largest movement first.
    """
    errors, tolerance = np.asarray(errors, dtype=float), np.asarray(tolerance, dtype=float)
    table = robot.table
    names = list(names if names is not None else robot.free_default)
    groups: dict[str, list[int]] = {}
    for name in names:
        k = table.index(name)
        if table.units[k] == "mm":
            groups.setdefault(_group(name), []).append(k)
    out = []
    for group, idx in groups.items():
        n, e = table.nominal[idx], errors[idx]
        varied = np.std(n) > 0.25 * np.sqrt(np.mean(n ** 2))  # equal values: a scale is a common offset
        if len(idx) < 3 or not varied or not np.any(np.abs(e) > PLAUSIBLE_TOLERANCES * tolerance[idx]):
            continue
        scale = float(n @ e / (n @ n))
        rest = e - scale * n
        if np.linalg.norm(rest) > PATTERN_FIT * np.linalg.norm(e) or scale <= -1.0:
            continue
        out.append(ScalePattern(group=group, names=tuple(table.names[k] for k in idx), scale=scale,
                                residual=float(np.sqrt(np.mean(rest ** 2))), largest_error=float(np.max(np.abs(e))),
                                largest=float(np.max(np.abs(e) / tolerance[idx]))))
    return sorted(out, key=lambda d: -d.largest)


# --------------------------------------------------------------------------- conversions


@dataclass(frozen=True)
class Conversion:
    """One mistake a file can hold, and its undoing.

    Attributes:
        name: short name (``"positions in metres"``, ``"x and y swapped"``, ``"joint 3 reversed"``).
        finding: what the file then seems to hold, in words (a message's clause).
        fix: what the conversion does to the file, in words.
        kind: ``"positions"``, ``"angles"`` or ``"joints"``: the columns it changes.
        apply: ``apply(joints, measured) -> (joints, measured)``, new arrays.
        axes: which of the kind's columns it changes (0-based: x, y, z; the angles; the joints);
            empty: every one.
    """

    name: str
    finding: str
    fix: str
    kind: str
    apply: Callable = field(repr=False, compare=False)
    axes: tuple = ()


def _positions(measured: np.ndarray, n_targets: int, robot: Robot) -> np.ndarray:
    """(N, K, 3) view-copy of the position columns (K targets, or the pose's x, y, z)."""
    if n_targets:
        return measured.reshape(len(measured), n_targets, 3).copy()
    return measured[:, ~robot.angle_pose_mask][:, None, :].copy()


def _with_positions(measured: np.ndarray, pos: np.ndarray, n_targets: int, robot: Robot) -> np.ndarray:
    out = measured.copy()
    if n_targets:
        return pos.reshape(len(measured), -1)
    out[:, ~robot.angle_pose_mask] = pos[:, 0, :]
    return out


def _position_conversion(robot, k, name, finding, fix, change, axes=()) -> Conversion:
    def apply(joints, measured):
        return joints.copy(), _with_positions(measured, change(_positions(measured, k, robot)), k, robot)
    return Conversion(name, finding, fix, "positions", apply, axes)


def _angle_conversion(robot, name, finding, fix, change, axes=()) -> Conversion:
    mask = robot.angle_pose_mask

    def apply(joints, measured):
        out = measured.copy()
        out[:, mask] = change(measured[:, mask])
        return joints.copy(), out
    return Conversion(name, finding, fix, "angles", apply, axes)


def _joint_conversion(name, finding, fix, change, axes=()) -> Conversion:
    return Conversion(name, finding, fix, "joints", lambda joints, measured: (change(joints.copy()), measured.copy()),
                      axes)


def _swap(a: int, b: int):
    def change(p):
        p[..., [a, b]] = p[..., [b, a]]
        return p
    return change


def _negate(a: int):
    def change(p):
        p[..., a] = -p[..., a]
        return p
    return change


def _position_conversions(robot: Robot, k: int) -> list[Conversion]:
    axes = "xyz"
    out = [_position_conversion(robot, k, "positions in metres", "the positions seem to be in metres",
                                "positions times 1000", lambda p: p * 1000.0)]
    for a, b in ((0, 1), (0, 2), (1, 2)):
        out.append(_position_conversion(robot, k, f"{axes[a]} and {axes[b]} swapped",
                                        f"the columns {axes[a]} and {axes[b]} seem to be swapped",
                                        f"{axes[a]} and {axes[b]} exchanged", _swap(a, b), (a, b)))
    for a in range(3):
        out.append(_position_conversion(robot, k, f"{axes[a]} sign flipped",
                                        f"the positions' {axes[a]} seems to have its sign flipped",
                                        f"{axes[a]} negated", _negate(a), (a,)))
    return out


def _xyz_convention(angles: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return euler_from_matrix(Rotation.from_euler("XYZ", angles).as_matrix())


def _angle_conversions(robot: Robot) -> list[Conversion]:
    names = [robot.pose_names[i] for i in np.flatnonzero(robot.angle_pose_mask)]
    out = [_angle_conversion(robot, "angles in degrees", "the angles seem to be in degrees", "angles times pi / 180",
                             np.deg2rad)]
    for a, n in enumerate(names):
        out.append(_angle_conversion(robot, f"{n} sign flipped", f"the angle {n} seems to have its sign flipped",
                                     f"{n} negated", _negate(a), (a,)))
    out += [
        _angle_conversion(robot, "R = Rx(alpha) Ry(beta) Rz(gamma)", "the angles seem to follow R = Rx(alpha) "
                          "Ry(beta) Rz(gamma)", "angles re-read in the convention Rx Ry Rz", _xyz_convention),
        _angle_conversion(robot, "inverse rotation", "the angles seem to follow the inverse rotation (base to "
                          "platform)", "rotation inverted",
                          lambda a: euler_from_matrix(np.swapaxes(rotation_matrix(a), 1, 2))),
        _angle_conversion(robot, "angles in reversed order", "the angles seem to follow the columns in the order "
                          f"{', '.join(reversed(names))}", "angle columns reversed", lambda a: a[:, ::-1].copy()),
    ]
    return out


def _joint_conversions(robot: Robot) -> list[Conversion]:
    """Joint units, and each joint read backwards: a motor (rad) counting the other way reads
    ``-q`` about its zero (its zero is the reference the geometry's offset ``q0`` refers to); a leg
    (mm) whose encoder counts the other way reads ``l_min + l_max - l`` (mirrored about the middle
    of its stroke, the home length)."""
    unit, sym, word = robot.joint_unit, robot.joint_symbol, robot.chain_word
    limits = robot.joint_limits()
    if unit == "mm":
        out = [_joint_conversion("joints in metres", "the joint values seem to be in metres", "joints times 1000",
                                 lambda q: q * 1000.0)]
    else:
        out = [_joint_conversion("joints in degrees", "the joint values seem to be in degrees",
                                 "joints times pi / 180", np.deg2rad)]
    for c in range(robot.n_chains):
        def change(q, c=c):
            q[:, c] = (limits[c].sum() - q[:, c]) if unit == "mm" else -q[:, c]
            return q
        how = (f"{sym}{c + 1} -> {limits[c].sum():.6g} - {sym}{c + 1} (about the middle of its range)" if unit == "mm"
               else f"{sym}{c + 1} -> -{sym}{c + 1} (about its zero)")
        out.append(_joint_conversion(f"joint {c + 1} reversed", f"{word} {c + 1}'s joint reading ({sym}{c + 1}) "
                                     "seems to count the other way", how, change, (c,)))
    return out


def conversion_registry(robot: Robot, n_targets: int = 0) -> tuple[Conversion, ...]:
    """Every conversion :func:`diagnose` tries on ``robot``'s data, in order: positions (metres,
    swapped axes, flipped signs), angles (degrees, flipped signs, other conventions; full poses
    with three angles only), joints (units, each joint reversed)."""
    out = _position_conversions(robot, n_targets)
    if n_targets == 0 and int(robot.angle_pose_mask.sum()) == 3:
        out += _angle_conversions(robot)
    return tuple(out + _joint_conversions(robot))


# --------------------------------------------------------------------------- fits


@dataclass(frozen=True, eq=False)
class FitFigures:
    """One fit's evidence.

    Attributes:
        chi2, dof: chi-square of the whitened residuals and its degrees of freedom (inf, 0 when
            the fit could not run).
        limit: the chi-square(dof) ``1 - FIT_ALPHA`` quantile.
        frame_estimated: whether an instrument frame was estimated.
        worst_parameter: the free parameter that moved most, in tolerances ('' when no fit).
        worst_tolerances: how many tolerances it moved (movements within :data:`SIGNIFICANT` of
            their standard deviations count as none).
        worst_offset, worst_unit, worst_tolerance: how far it moved from nominal, its unit and its
            tolerance.
        error: why the fit could not run ('' when it ran).
        fit: the :class:`calib.measurement.MeasuredFit` (None when it could not run).
    """

    chi2: float
    dof: int
    limit: float
    frame_estimated: bool = False
    worst_parameter: str = ""
    worst_tolerances: float = float("inf")
    worst_offset: float = float("nan")
    worst_unit: str = ""
    worst_tolerance: float = float("nan")
    error: str = ""
    fit: object = field(default=None, repr=False)

    @property
    def frame_turn(self) -> float:
        """The estimated instrument frame's rotation angle (rad; 0 without a frame): of several
        mirror images that fit with a frame, the one needing the least turn is the file's mistake
        (the others add a half turn to it)."""
        if not self.frame_estimated or self.fit is None:
            return 0.0
        R = rotation_matrix(np.asarray(self.fit.frame, dtype=float)[3:6][None])[0]
        return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))

    @property
    def chi2_dof(self) -> float:
        """Chi-square per degree of freedom (inf when nothing can be judged)."""
        return self.chi2 / self.dof if self.dof > 0 else float("inf")

    @property
    def fits(self) -> bool:
        """At the declared noise: chi-square within :attr:`limit`."""
        return bool(np.isfinite(self.chi2) and self.chi2 <= self.limit)

    @property
    def plausible(self) -> bool:
        """No free parameter beyond :data:`PLAUSIBLE_TOLERANCES` tolerances."""
        return bool(self.worst_tolerances <= PLAUSIBLE_TOLERANCES)

    def words(self) -> str:
        """``chi-square 0.98 per degree of freedom (limit 1.27)``, with the frame and the worst parameter."""
        if self.error:
            return f"no fit ({self.error})"
        s = f"chi-square {self.chi2_dof:.3g} per degree of freedom (limit {self.limit / max(self.dof, 1):.3g})"
        if self.frame_estimated:
            s += ", instrument frame estimated"
        if not self.plausible:
            s += f", {self.moved_words()}"
        return s

    def moved_words(self) -> str:
        """``P5.x moved 2.9 mm from nominal (tolerance 0.1 mm)``."""
        return (f"{self.worst_parameter} moved {self.worst_offset:.3g} {self.worst_unit} from nominal "
                f"(tolerance {self.worst_tolerance:.3g} {self.worst_unit})")

    def summary(self) -> dict:
        """JSON-ready figures."""
        finite = lambda v: float(v) if np.isfinite(v) else None  # noqa: E731
        return {"chi2": finite(self.chi2), "dof": self.dof, "chi2_per_dof": finite(self.chi2_dof),
                "limit_per_dof": finite(self.limit / self.dof) if self.dof > 0 else None, "fits": self.fits,
                "plausible": self.plausible, "frame_estimated": self.frame_estimated,
                "worst_parameter": self.worst_parameter or None, "worst_tolerances": finite(self.worst_tolerances),
                "worst_offset": finite(self.worst_offset), "worst_unit": self.worst_unit or None,
                "error": self.error or None}


@dataclass(frozen=True)
class _Problem:
    robot: Robot
    noise: SensorNoise
    frame: str
    targets: np.ndarray | None
    estimate_targets: bool | None
    tolerance: np.ndarray
    free: np.ndarray
    sessions: np.ndarray | None = None


def _sessions_on(frame, sessions, rows) -> tuple:
    """``(frame, sessions)`` of ``rows`` alone: the sessions present among them numbered 0, 1, ...
    with their frame modes (one session left: None and its mode)."""
    if sessions is None:
        return frame, None
    present, inverse = np.unique(np.asarray(sessions)[rows], return_inverse=True)
    modes = frame if isinstance(frame, str) else [frame[int(k)] for k in present]
    if present.size == 1:
        return (modes if isinstance(modes, str) else modes[0]), None
    return modes, inverse


def _on_rows(problem: _Problem, rows) -> _Problem:
    """``problem`` for ``rows`` alone (:func:`_sessions_on`)."""
    if problem.sessions is None:
        return problem
    frame, sessions = _sessions_on(problem.frame, problem.sessions, rows)
    return replace(problem, frame=frame, sessions=sessions)


def _figures(problem: _Problem, joints, measured, screen: bool = False, as_written: bool = False) -> FitFigures:
    """Fit the geometry (and frame) to ``(joints, measured)`` (``screen``: the cheap fit of
    :data:`SCREEN_ITERATIONS`); its figures, also on failure."""
    robot = problem.robot
    how = ({"solver": "gn", "max_iter": SCREEN_ITERATIONS, "gauge_passes": 1} if screen else
           {"max_iter": FULL_ITERATIONS})
    try:
        fit = identify_measured(robot, joints, measured, problem.noise, frame=problem.frame, targets=problem.targets,
                                estimate_targets=problem.estimate_targets, sessions=problem.sessions, **how)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:  # KinematicsError is a ValueError
        return FitFigures(float("inf"), 0, float("inf"), error=str(exc).split("\n")[0])
    r = fit.result
    chi2 = float(r.chi2) if np.isfinite(r.chi2) and np.all(np.isfinite(r.residuals)) else float("inf")
    offset = np.abs(r.theta - robot.table.nominal)[problem.free]
    # A movement counts where the rows place it (beyond SIGNIFICANT standard deviations): a plain
    # fit of poses that leave a combination undetermined (one plane) moves it anywhere, and that is
    # no evidence of a mistake in the file.
    # The data as written (``as_written``) are blamed only on a decisive movement, beyond DECISIVE of
    # its standard deviations: a level grid leaves combinations nearly free and a plain fit drifts
    # them a metre at 6 standard deviations (no evidence against the file), where a file in the
    # wrong unit moves the geometry tens of them. A conversion, to be named, must be plausible
    # without that benefit of the doubt.
    std, tol = r.std[problem.free], problem.tolerance[problem.free]
    counted = offset > (DECISIVE if as_written else SIGNIFICANT) * std
    moved = np.where(counted, offset / tol, 0.0)
    worst = int(np.argmax(moved)) if moved.size else 0
    k = problem.free[worst] if moved.size else 0
    return FitFigures(chi2, int(r.dof), chi2_limit(int(r.dof)), bool(fit.frame_estimated),
                      robot.table.names[k] if moved.size else "",
                      float(moved[worst]) if moved.size and np.isfinite(moved[worst]) else float("inf"),
                      worst_offset=float(offset[worst]) if moved.size else float("nan"),
                      worst_unit=robot.table.units[k] if moved.size else "",
                      worst_tolerance=float(problem.tolerance[k]) if moved.size else float("nan"), fit=fit)


def _screen_rows(problem: _Problem, n: int, m: int) -> np.ndarray:
    """Evenly spaced rows for the screen: :data:`SCREEN_ROWS_FACTOR` times the fewest rows that
    identify the unknowns (free parameters, a frame a session, target offsets), or every row."""
    k = 0 if problem.targets is None else len(problem.targets)
    frames = 1 if problem.sessions is None else int(np.max(problem.sessions, initial=0)) + 1
    unknowns = problem.free.size + 6 * frames + (3 * k if problem.estimate_targets is not False else 0)
    want = SCREEN_ROWS_FACTOR * -(-unknowns // m)
    return np.arange(n) if want >= n else np.unique(np.linspace(0, n - 1, want).round().astype(int))


# --------------------------------------------------------------------------- the verdict


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Whether a data set fits its machine and, if not, the likely cause with its evidence.

    Attributes:
        cause: one of :data:`CAUSES`.
        success: the data as written fit the machine plausibly (``cause == "none"``).
        message: the verdict in words, with its figures (no row numbers: :attr:`gross_rows` are
            0-based, the caller numbers rows for the user).
        written: the fit of the data as written.
        conversion: the conversion named (``cause == "conversion"``), else None.
        converted: the fit of the data so converted (None without a conversion).
        alternatives: other conversions that fit as well (with an instrument frame), by name.
        column: the column not measured (``cause == "unmeasured column"``), else None.
        gross_rows: 0-based rows named gross (``cause == "gross rows"``).
        screened: ``(name, chi-square per degree of freedom)`` of every conversion screened,
            best first (empty when the data fit as written).
        fits: fits run in all; seconds: wall time.
    """

    cause: str
    message: str
    written: FitFigures
    conversion: Conversion | None = None
    converted: FitFigures | None = None
    alternatives: tuple = ()
    column: str | None = None
    gross_rows: tuple = ()
    screened: tuple = ()
    fits: int = 0
    seconds: float = 0.0
    rows: str = "every row"

    @property
    def success(self) -> bool:
        return self.cause == "none"

    def summary(self) -> dict:
        """JSON-ready verdict (rows 0-based under ``gross_rows``)."""
        c = self.conversion
        return {"cause": self.cause, "success": self.success, "message": self.message,
                "written": self.written.summary(), "conversion": None if c is None else c.name,
                "conversion_fix": None if c is None else c.fix,
                "converted": None if self.converted is None else self.converted.summary(),
                "alternatives": list(self.alternatives), "column": self.column,
                "gross_rows": [int(r) for r in self.gross_rows], "fits": self.fits, "seconds": self.seconds,
                "rows": self.rows}


def _named(written: FitFigures, converted: FitFigures) -> bool:
    """The evidence that names a conversion: the converted data fit plausibly, and as written
    they misfit by at least :data:`MIN_IMPROVEMENT` times the converted chi-square per degree of
    freedom, or fit only implausibly."""
    if not (converted.fits and converted.plausible):
        return False
    if not written.fits:
        return written.chi2_dof >= MIN_IMPROVEMENT * converted.chi2_dof
    return not written.plausible


#: Frame turns (rad) closer than this count as equal when conversions are ranked.
TURN_RESOLUTION = 0.05


def _preference(figures: FitFigures) -> tuple:
    """How a conversion that fits ranks: no instrument frame first, then the least turned frame
    (to :data:`TURN_RESOLUTION`), then the smaller chi-square per degree of freedom."""
    return (figures.frame_estimated, round(figures.frame_turn / TURN_RESOLUTION), figures.chi2_dof)


def _conversions(problem: _Problem, joints, measured, written: FitFigures, counter: list) -> dict:
    """Screen every conversion on a subset of rows; fit on all rows the best :data:`SCREEN_KEEP`
    of those within :data:`MIN_IMPROVEMENT` times the smaller of the best screened chi-square per
    degree of freedom and the data's as written (at least 1: a conversion must beat both), or,
    where the data as written fit (only implausibly), the best screened alone;
    ``{"screened": ((name, chi2/dof), ...), "named": [(Conversion, FitFigures), ...]}`` best first.

    Data that fit only implausibly set no chi-square for a conversion to beat: it is named on
    plausibility. A machine of revolute joints (Delta, 6-RUS) in metres fits as written, a
    thousand times smaller, and its screen (two Gauss-Newton steps from the nominal geometry, an
    upper bound) stops far above the limit where the full fit reaches it: a 6-RUS recording of
    errors of 2.5 tolerances, positions in metres, screened 3.9e4 per degree of freedom and fitted
    0.55 converted."""
    k = 0 if problem.targets is None else len(problem.targets)
    rows = _screen_rows(problem, *measured.shape)
    sub = _on_rows(problem, rows)
    screened = []
    for conv in conversion_registry(problem.robot, k):
        q, m = conv.apply(joints, measured)
        screened.append((conv, _figures(sub, q[rows], m[rows], screen=True)))
        counter[0] += 1
    screened.sort(key=lambda cf: cf[1].chi2_dof)
    best = screened[0][1].chi2_dof if screened else float("inf")
    window = MIN_IMPROVEMENT * max(1.0, best if written.fits else min(written.chi2_dof, best))
    # Of those within the window, the ones that fit as they are (no frame, or the least turned)
    # first: with a frame every mirror image of positions fits, and the screen's chi-squares
    # differ by the frame's degrees of freedom alone.
    within = sorted([cf for cf in screened if cf[1].chi2_dof <= window], key=lambda cf: _preference(cf[1]))
    named = []
    for conv, _ in within[:SCREEN_KEEP]:
        q, m = conv.apply(joints, measured)
        figures = _figures(problem, q, m)
        counter[0] += 1
        if _named(written, figures):
            named.append((conv, figures))
    named.sort(key=lambda cf: _preference(cf[1]))
    return {"screened": tuple((c.name, f.chi2_dof) for c, f in screened), "named": named}


def _constant_column(problem: _Problem, joints, measured) -> tuple[str, str] | None:
    """``(column, words)`` for a pose column holding one value on every row while the nominal
    model moves the platform along it by more than :data:`CONSTANT_COLUMN_STDS` noise standard
    deviations; None otherwise (and for target positions)."""
    robot = problem.robot
    if problem.targets is not None or len(measured) < 2:
        return None
    try:
        fk = robot.forward_kinematics(robot.table.nominal, joints)
    except KinematicsError:
        return None
    std = problem.noise.pose_std(robot.pose_units)
    for j, name in enumerate(robot.pose_names):
        spread = float(np.ptp(fk[:, j]))
        if np.ptp(measured[:, j]) == 0 and spread > CONSTANT_COLUMN_STDS * std[j]:
            unit = robot.pose_units[j]
            return name, (f"the column {name} holds one value ({measured[0, j]:.6g} {unit}) on every row while the "
                          f"joints move the platform over {spread:.4g} {unit} along it: the column was not measured")
    return None


def _unexplained(problem: _Problem, joints, measured, written: FitFigures, screened: tuple, counter: list,
                 gross: bool) -> dict:
    """The verdict when no conversion explains the data: a column not measured, gross rows
    (:func:`calib.robust.find_gross_rows`), or the model misfits. Keyword arguments of :class:`Diagnosis`."""
    robot = problem.robot
    column = _constant_column(problem, joints, measured)
    if column is not None:
        return {"cause": "unmeasured column", "column": column[0], "message": column[1]}
    best = f"; the best conversion screened, {screened[0][0]}, gives {screened[0][1]:.3g}" if screened else ""
    tried = (f"as written ({written.words()}), nor after any of the {len(screened)} conversions tried"
             f"{best}")
    gross = gross and problem.sessions is None  # the search knows one instrument frame
    if gross:
        from .robust import find_gross_rows

        try:
            found = find_gross_rows(robot, joints, measured, problem.noise, frame=problem.frame,
                                    targets=problem.targets, estimate_targets=problem.estimate_targets)
        except ValueError:
            found = None
        counter[0] += 0 if found is None else found.fits
        if found is not None and found.success and found.gross:
            return {"cause": "gross rows", "gross_rows": tuple(int(r) for r in found.gross),
                    "message": (f"{len(found.gross)} of {len(joints)} rows disagree grossly with the others, which "
                                f"fit the {robot.name} at the declared noise; the data do not fit {tried}")}
        if found is not None and found.success:  # every row consistent: the capped fit stopped early
            return {"cause": "none", "message": f"the data fit the {robot.name} at the declared noise "
                                                f"(the robust fit judged every row consistent; {found.message})"}
    return {"cause": "left-out physics",
            "message": (f"the data do not fit the {robot.name} at the declared noise {tried}"
                        f"{', nor without gross rows' if gross else ''}: an effect the geometric model leaves "
                        "out, or noise declared too small")}


def _fit_words(robot: Robot, written: FitFigures, tolerance: np.ndarray) -> str:
    if written.plausible:
        return f"the data fit the {robot.name} at the declared noise ({written.words()}): nothing wrong"
    pattern = [] if written.fit is None else description_pattern(robot, written.fit.result.errors, tolerance)
    if pattern:
        return (f"the data fit the {robot.name} at the declared noise, but only with {written.moved_words()}, and "
                f"the fitted errors are a pattern of the description, not physics: {pattern[0].words()}: the "
                "nominal geometry described seems to be another machine's")
    return (f"the data fit the {robot.name} at the declared noise, but only with {written.moved_words()} "
            f"(chi-square {written.chi2_dof:.3g} per degree of freedom) and no conversion "
            "of the file fits better: an offset the geometry absorbs (a capture body mounted turned on the "
            "platform turns the platform joints' coordinates) or a machine far from its nominal geometry")


def diagnose(robot: Robot, joints, measured, noise: SensorNoise, *, frame="auto", targets=None,
             estimate_targets: bool | None = None, tolerance=None, gross: bool = True, sessions=None) -> Diagnosis:
    """Judge whether ``(joints, measured)`` fit ``robot`` at the declared ``noise``; if not, name
    the likely cause with its evidence (module doc).

    Args:
        robot: the robot (its nominal geometry starts every fit).
        joints: (N, C) joints as recorded, the robot's joint unit.
        measured: (N, D) full poses, or (N, 3K) target positions with ``targets``, as recorded.
        noise: declared noise.
        frame: instrument frame mode (:data:`calib.measurement.FRAME_MODES`), for the data as
            written and every conversion; or one a session (``sessions``).
        targets, estimate_targets: target offsets, as :func:`calib.measurement.identify_measured`.
        tolerance: ``parameter_tolerance`` mapping (:meth:`calib.prior.ParameterPrior.from_tolerance`);
            default the robot's.
        gross: look for gross rows (:func:`calib.robust.find_gross_rows`) when no conversion fits
            (one session only: the search knows one instrument frame).
        sessions: (N,) int, each row's session (its own instrument frame; every fit has one frame
            a session, as :func:`calib.measurement.identify_measured`), or None: one.

    Above :data:`DIAGNOSIS_MAX_ROWS` rows a seeded subsample of that many rows is judged (its
    ``rows`` says so; ``gross_rows`` are then rows of the subsample, numbered in the input).

    Returns:
        A :class:`Diagnosis`; never raises on data that cannot be fitted (their fit says why).
    """
    joints, measured = np.array(joints, dtype=float), np.array(measured, dtype=float)
    sessions = None if sessions is None else np.asarray(sessions, dtype=int)
    n = len(joints)
    if n <= DIAGNOSIS_MAX_ROWS:
        return _diagnose(robot, joints, measured, noise, frame, targets, estimate_targets, tolerance, gross, sessions)
    sub = np.sort(np.random.default_rng(n).choice(n, size=DIAGNOSIS_MAX_ROWS, replace=False))
    frame_sub, sessions_sub = _sessions_on(frame, sessions, sub)
    found = _diagnose(robot, joints[sub], measured[sub], noise, frame_sub, targets, estimate_targets, tolerance, gross,
                      sessions_sub)
    return replace(found, gross_rows=tuple(int(sub[i]) for i in found.gross_rows),
                   rows=f"a seeded subsample of {DIAGNOSIS_MAX_ROWS:,} of the {n:,} rows ({n:,} rows > "
                        f"DIAGNOSIS_MAX_ROWS = {DIAGNOSIS_MAX_ROWS})")


def _diagnose(robot, joints, measured, noise, frame, targets, estimate_targets, tolerance, gross,
              sessions=None) -> Diagnosis:
    """:func:`diagnose` of every row given."""
    t0 = time.perf_counter()
    problem = _Problem(robot, noise, frame, None if targets is None else np.asarray(targets, dtype=float),
                       estimate_targets, ParameterPrior.from_tolerance(robot, tolerance).std,
                       np.sort(robot.table.indices(robot.free_default)), sessions)
    counter = [1]
    written = _figures(problem, joints, measured, as_written=True)
    if written.fits and written.plausible:
        return Diagnosis("none", _fit_words(robot, written, problem.tolerance), written, fits=1, seconds=time.perf_counter() - t0)
    found = _conversions(problem, joints, measured, written, counter)
    if found["named"]:
        conv, figures = found["named"][0]
        how = ("do not" if not written.fits else "fit only implausibly") + f" ({written.words()})"
        message = (f"{conv.finding}: converted ({conv.fix}) the data fit the {robot.name} at the declared noise "
                   f"({figures.words()}); as written they {how}")
        return Diagnosis("conversion", message, written, conv, figures, tuple(c.name for c, _ in found["named"][1:]),
                         screened=found["screened"], fits=counter[0], seconds=time.perf_counter() - t0)
    if written.fits:
        return Diagnosis("none", _fit_words(robot, written, problem.tolerance), written, screened=found["screened"], fits=counter[0],
                         seconds=time.perf_counter() - t0)
    verdict = _unexplained(problem, joints, measured, written, found["screened"], counter, gross)
    return Diagnosis(written=written, screened=found["screened"], fits=counter[0],
                     seconds=time.perf_counter() - t0, **verdict)


# --------------------------------------------------------------------------- other readings of a file


@dataclass(frozen=True, eq=False)
class Comparison:
    """The data as read beside other readings of the same file (a lab's mapping with one key
    changed: another unit, the quaternion's scalar at the other end...), judged as
    :func:`diagnose` judges its conversions.

    Attributes:
        written: the fit of the data as read.
        figures: ``{name: FitFigures}`` of the readings given the full fit (the best
            :data:`SCREEN_KEEP` screened within :data:`MIN_IMPROVEMENT` times the smaller of the best
            screened chi-square per degree of freedom and the data's as read, at least 1).
        screened: ``((name, chi-square per degree of freedom), ...)`` of every reading's screening
            fit, best first.
        named: the readings the evidence names over the data as read (:func:`diagnose`'s rule:
            they fit plausibly, and as read the data misfit by at least :data:`MIN_IMPROVEMENT`
            times their chi-square per degree of freedom, or fit only implausibly), best first
            (no instrument frame first, then the smallest chi-square).
        also_fit: readings that fit plausibly while the data as read fit plausibly too: the rows
            cannot tell them apart (weak evidence), best first.
        fits, seconds: fits run; wall time.
    """

    written: FitFigures
    figures: dict
    screened: tuple
    named: tuple
    also_fit: tuple
    fits: int = 0
    seconds: float = 0.0


def compare_readings(robot: Robot, joints, measured, noise: SensorNoise, readings: dict, *, frame="auto",
                     sessions=None, targets=None, estimate_targets: bool | None = None,
                     tolerance=None) -> Comparison:
    """Judge the data as read (``joints``, ``measured``) against other readings of the same file
    with :func:`diagnose`'s fits and rule (module doc): a screen of every reading, full fits of
    the best, a reading named only on evidence.

    Args:
        robot, joints, measured, noise, targets, estimate_targets, tolerance: as :func:`diagnose`.
        readings: ``{name: (joints (N, C), measured (N, D))}``, the same rows read otherwise.
        frame: instrument frame mode, or one per session (:func:`calib.measurement.identify_measured`).
        sessions: (N,) int, each row's session (its own instrument frame), or None: one.

    Returns:
        A :class:`Comparison`; never raises on data that cannot be fitted (their fit says why).
    """
    t0 = time.perf_counter()
    joints, measured = np.array(joints, dtype=float), np.array(measured, dtype=float)
    sessions = None if sessions is None else np.asarray(sessions, dtype=int)
    problem = _Problem(robot, noise, frame, None if targets is None else np.asarray(targets, dtype=float),
                       estimate_targets, ParameterPrior.from_tolerance(robot, tolerance).std,
                       np.sort(robot.table.indices(robot.free_default)), sessions)
    written = _figures(problem, joints, measured, as_written=True)
    rows = _screen_rows(problem, *measured.shape)
    if sessions is not None and len(np.unique(sessions[rows])) < len(np.unique(sessions)):
        rows = np.arange(len(measured))  # every session keeps rows in the screen
    sub = _Problem(robot, noise, frame, problem.targets, estimate_targets, problem.tolerance, problem.free,
                   None if sessions is None else np.unique(sessions[rows], return_inverse=True)[1])
    screened = sorted(((name, _figures(sub, np.asarray(q, float)[rows], np.asarray(m, float)[rows], screen=True))
                       for name, (q, m) in readings.items()), key=lambda nf: nf[1].chi2_dof)
    best = screened[0][1].chi2_dof if screened else float("inf")
    window = MIN_IMPROVEMENT * max(1.0, min(written.chi2_dof, best))
    figures = {name: _figures(problem, *(np.asarray(a, float) for a in readings[name]))
               for name, f in [nf for nf in screened if nf[1].chi2_dof <= window][:SCREEN_KEEP]}
    order = sorted(figures, key=lambda n: (figures[n].frame_estimated, figures[n].chi2_dof))
    good = written.fits and written.plausible
    return Comparison(written, figures, tuple((n, f.chi2_dof) for n, f in screened),
                      tuple(n for n in order if _named(written, figures[n])),
                      tuple(n for n in order if good and figures[n].fits and figures[n].plausible),
                      fits=1 + len(screened) + len(figures), seconds=time.perf_counter() - t0)
