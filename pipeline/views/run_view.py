"""The Rerun view of a calibration run, for any robot (rerun-sdk 0.41 API).

Each tool writes with its own application id per robot (:func:`pipeline.views.charts.application_id`)
and its own default blueprint, so that files of different tools or robots opened together keep their layouts. What a calibration run
(:func:`log_calibration_run`) writes, all lengths in mm unless the name says um:

* ``machine/{nominal,actual,calibrated}/chains|platform``: the machine at each calibration pose
  (timeline ``pose``): nominal geometry at the intended pose, actual geometry (or, for a real
  machine, the identified one) at the measured pose, identified geometry at the pose it predicts.
  Departures from the nominal machine are drawn magnified (:func:`magnification`, written in the
  view's key ``machine/key``); ``machine/chain_labels``: one colour per chain. Above
  :data:`MAX_MACHINE_POSES` calibration poses the machines and the arrows below are drawn at
  evenly spaced poses only (at most that many, each at its own step of the ``pose`` timeline; the
  key says so); the residual series keep every pose.
* ``machine/errors/{before,after}``: static arrows at every calibration pose, position error
  before (measured - intended) and after (measured - calibrated prediction), same magnification,
  coloured by magnitude (the scale is in the key); ``machine/flagged``: outlier poses.
* ``residuals/{before,after}_um``: closure (joint-space) residual of each chain per calibration
  pose (timeline ``pose``) with the nominal and the identified model; ``residuals/flagged``.
* ``heldout/position_error_um``, ``heldout/orientation_error_urad``: per held-out pose (timeline
  ``pose``), before and after compensation.
* ``convergence/chart``: log-scale chart of max dQint (or cost) per iteration (static; the same
  values as ``convergence/log10`` on timeline ``iteration``).
* ``parameters/chart``: named bars, identified (+-2 sigma) beside injected, one scale.
* ``observability``: see :mod:`pipeline.views.observability`; ``summary``: the run's report as
  markdown (:func:`pipeline.report.text.report_markdown`, given to :func:`log_calibration_run`).

The charts are drawn with :mod:`pipeline.views.charts`.
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.robot import Robot

from .charts import (FLAG_COLOR, MACHINE_COLORS, chain_colors, chart_view, log_named_bars, log_plot,
                     log_series_by_pose, magnification, magnitude_colors)
from .observability import log_observability, observability_views

__all__ = ["log_calibration_run", "blueprint", "run_eye", "run_magnification", "MAX_MACHINE_POSES", "drawn_poses"]

#: The 3D machines and error arrows of a run are drawn at no more than this many calibration
#: poses (evenly spaced; every pose below it): three machines of C chains at 100,000 poses are
#: millions of line strips, a recording the viewer loads slowly and nobody reads pose by pose.
MAX_MACHINE_POSES = 2000


def drawn_poses(n: int) -> np.ndarray:
    """0-based indices of the calibration poses drawn in 3D: every one up to
    :data:`MAX_MACHINE_POSES`, else that many evenly spaced (first and last included)."""
    if n <= MAX_MACHINE_POSES:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, MAX_MACHINE_POSES).round().astype(int))


# -- the calibration run -------------------------------------------------------------------------
def _log_machine(rec: rr.RecordingStream, path: str, points: np.ndarray, color, radius: float,
                 steps: np.ndarray | None = None) -> None:
    """``points``: (N, C, K, 3) chain polylines of N poses, one pose a step of the ``pose``
    timeline (``steps`` (N,), default 0 .. N - 1; sent as columns: one call per entity, not one
    per pose); the platform joins the chains' last points."""
    n, c = points.shape[:2]
    tips = points[:, :, -1]
    platform = np.concatenate([tips, tips[:, :1]], axis=1)  # (N, C + 1, 3): one closed strip a pose
    index = [rr.TimeColumn("pose", sequence=np.arange(n) if steps is None else steps)]
    style = rr.LineStrips3D.columns(colors=[color] * n, radii=[radius] * n)
    for part, strips, per_pose in (("chains", points.reshape(n * c, *points.shape[2:]), c), ("platform", platform, 1)):
        rec.send_columns(f"{path}/{part}", indexes=index,
                         columns=[*rr.LineStrips3D.columns(strips=strips).partition([per_pose] * n), *style])


def _eye(points: np.ndarray) -> rrb.EyeControls3D:
    """A camera that frames every point (from the front-right, slightly above)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    c = (lo + hi) / 2
    r = float(np.linalg.norm(hi - lo)) / 2
    d = np.array([1.0, -1.6, 0.9])
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=c + 3.0 * r * d / np.linalg.norm(d),
                             look_target=c, eye_up=(0.0, 0.0, 1.0))


def _scene(robot: Robot, nominal, targets) -> np.ndarray:
    joints = robot.inverse_kinematics(nominal, targets)
    return robot.chain_points(nominal, joints, targets)


def blueprint(robot: Robot | None = None, *, eye: rrb.EyeControls3D | None = None, magnified: float = 1.0,
              has_heldout: bool = True, history_label: str = "max dQint", has_truth: bool = True) -> rrb.Blueprint:
    """The run file's layout: machine | per-chain residuals, held-out, convergence | parameters |
    summary, observability. Every view shows data on the ``pose`` timeline, active at open.
    ``has_truth``: the injected errors are known (a simulated machine): the parameters' chart is
    "identified vs injected"; on real data "identified (+-2 sigma)"."""
    word = robot.chain_word if robot is not None else "chain"
    angles = robot is None or bool(robot.angle_pose_mask.any())
    series = [
        rrb.TimeSeriesView(origin="residuals/before_um", name=f"Closure residual per {word}, nominal model (um) vs pose",
                           plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop)),
        rrb.TimeSeriesView(origin="residuals/after_um", name=f"Closure residual per {word}, identified model (um) vs pose",
                           plot_legend=rrb.PlotLegend(visible=False)),
    ]
    if has_heldout:
        held = [rrb.TimeSeriesView(origin="heldout/position_error_um",
                                   name="Held-out position error (um) vs held-out pose")]
        if angles:
            held.append(rrb.TimeSeriesView(origin="heldout/orientation_error_urad",
                                           name="Held-out orientation error (urad) vs held-out pose"))
        series.append(rrb.Tabs(*held) if len(held) > 1 else held[0])
    series.append(chart_view("convergence/chart", f"Convergence: {history_label} per iteration (log)"))
    machine = rrb.Spatial3DView(origin="machine", name=f"Machine at the pose (departures from nominal x{magnified:g})",
                                eye_controls=eye, line_grid=rrb.LineGrid3D(visible=False))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(machine, rrb.TextDocumentView(origin="key", name="Key"), row_shares=[5, 1]),
            rrb.Vertical(*series, row_shares=[3.0] + [2.0] * (len(series) - 2) + [1.5]),  # room for each leg's legend
            chart_view("parameters/chart", "Parameter errors: identified vs injected" if has_truth else
                       "Parameter errors: identified (+-2 sigma)"),
            rrb.Vertical(
                rrb.TextDocumentView(origin="summary", name="Summary"),
                observability_views("observability", "Observability"),
                row_shares=[1, 1],
            ),
            column_shares=[2.6, 2.0, 2.4, 2.0],
        ),
        rrb.TimePanel(timeline="pose", play_state="paused", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        collapse_panels=True,
    )


def _bar_unit(robot: Robot):
    """Parameter errors drawn in um; an angle as the arc it makes at the machine's size."""
    angle = robot.table.angle_mask()
    return np.where(angle, 1e3 * robot.length_scale_mm, 1e3), angle.any()


def _log_machines(rec: rr.RecordingStream, robot: Robot, thetas, joints: np.ndarray, targets: np.ndarray,
                  measured: np.ndarray, predicted: np.ndarray, m: float, chains: list[str],
                  steps: np.ndarray | None = None) -> float:
    """The three machines at every calibration pose (timeline ``pose``) and the chain labels.

    ``thetas``: (nominal, drawn, identified) parameter vectors, (P,) each (``drawn``: the actual
    machine, or the identified one for a real machine); ``joints`` (N, C); ``targets``,
    ``measured``, ``predicted``: (N, D) poses (mm, rad); ``m``: the departures' magnification.
    ``steps``: (N,) the poses' steps of the ``pose`` timeline (default 0 .. N - 1).
    Returns the machine's size (mm: the largest extent of the nominal machine over the poses).
    """
    nominal, drawn, identified = thetas
    n, c = joints.shape
    steps = np.arange(n) if steps is None else steps
    rec.log("machine", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    nominal_joints = robot.inverse_kinematics(nominal, targets)
    nom = robot.chain_points(nominal, nominal_joints, targets)
    act = robot.chain_points(drawn, joints, measured)
    cal = robot.chain_points(identified, joints, predicted)
    size = float(np.ptp(nom.reshape(-1, 3), axis=0).max())
    _log_machine(rec, "machine/nominal", nom, MACHINE_COLORS["nominal"], size * 0.006, steps)
    _log_machine(rec, "machine/actual", nom + m * (act - nom), MACHINE_COLORS["actual"], size * 0.004, steps)
    _log_machine(rec, "machine/calibrated", nom + m * (cal - nom), MACHINE_COLORS["calibrated"], size * 0.0022, steps)
    per_chain = rr.Points3D.columns(positions=nom[:, :, 0].reshape(-1, 3), labels=chains * n,
                                    colors=np.tile(np.asarray(chain_colors(c), dtype=np.uint8), (n, 1))
                                    ).partition([c] * n)
    rec.send_columns("machine/chain_labels", indexes=[rr.TimeColumn("pose", sequence=steps)],
                     columns=[*per_chain, *rr.Points3D.columns(radii=[size * 0.012] * n, show_labels=[True] * n)])
    return size


def _log_pose_errors(rec: rr.RecordingStream, robot: Robot, targets: np.ndarray, measured: np.ndarray,
                     predicted: np.ndarray, m: float, size: float, flagged: list[int],
                     shown: np.ndarray | None = None) -> float:
    """Arrows of the position error at the calibration poses ``shown`` (0-based; default every
    one), before (measured - intended) and after (measured - predicted), magnified ``m`` times,
    and rings at the ``flagged`` poses. ``targets``, ``measured``, ``predicted``: (N, D) poses
    (mm, rad); ``size``: the machine's (mm). Returns the colour scale's top (um): the largest
    error before over every pose."""
    pos = ~robot.angle_pose_mask
    centre = targets[:, pos][:, :3]
    before = (measured - targets)[:, pos][:, :3]
    after = (measured - predicted)[:, pos][:, :3]
    mag_b, mag_a = np.linalg.norm(before, axis=1) * 1e3, np.linalg.norm(after, axis=1) * 1e3
    vmax = float(np.nanmax(mag_b)) if len(targets) else 1.0
    shown = np.arange(len(targets)) if shown is None else shown
    rec.log("machine/errors/before", rr.Arrows3D(origins=centre[shown], vectors=m * before[shown],
                                                 colors=magnitude_colors(mag_b[shown], vmax), radii=size * 0.004,
                                                 labels=[f"pose {k + 1}: {mag_b[k]:.0f} um" for k in shown],
                                                 show_labels=False),
            static=True)
    rec.log("machine/errors/after", rr.Arrows3D(origins=centre[shown], vectors=m * after[shown],
                                                colors=magnitude_colors(mag_a[shown], vmax), radii=size * 0.002),
            static=True)
    if flagged:
        rec.log("machine/flagged", rr.Points3D(centre[flagged], radii=size * 0.02, colors=FLAG_COLOR,
                                               labels=[f"flagged pose {k + 1}" for k in flagged], show_labels=True),
                static=True)
    return vmax


def _log_key(rec: rr.RecordingStream, robot: Robot, m: float, vmax_um: float, *, simulated: bool,
             flagged: bool, drawn: str = "") -> None:
    """The 3D view's key: the machines' colours, the magnification, the arrows' colour scale."""
    what = "actual" if simulated else "measured (identified geometry)"
    key = (f"**grey** nominal, **orange** {what}, **blue** calibrated model; departures from nominal and "
           f"error arrows drawn **x{m:g}**. Arrows: position error at each calibration pose, thick before "
           f"(measured - intended), thin after (measured - calibrated), colour green 0 to red {vmax_um:.0f} um. "
           + ("Red ring: flagged pose. " if flagged else "") + f"Labels: one colour per {robot.chain_word}."
           + (f" {drawn}" if drawn else ""))
    rec.log("key", rr.TextDocument(key, media_type=rr.MediaType.MARKDOWN), static=True)


def _log_residuals(rec: rr.RecordingStream, robot: Robot, nominal: np.ndarray, identified: np.ndarray,
                   joints: np.ndarray, measured: np.ndarray, chains: list[str], flagged: list[int]) -> None:
    """Joint-space (closure) residual of each chain per calibration pose (um, timeline ``pose``),
    nominal and identified model; the flagged poses marked at their largest residual."""
    colors = chain_colors(len(chains))
    for name, theta in (("before", nominal), ("after", identified)):
        res = robot.closure(theta, joints, measured) * 1e3
        log_series_by_pose(rec, f"residuals/{name}_um", res, chains, colors)
        if flagged:
            rec.log(f"residuals/{name}_um/flagged", rr.SeriesPoints(colors=FLAG_COLOR, names="flagged pose",
                                                                    marker_sizes=6.0), static=True)
            rec.send_columns(f"residuals/{name}_um/flagged", indexes=[rr.TimeColumn("pose", sequence=flagged)],
                             columns=rr.Scalars.columns(scalars=np.abs(res[flagged]).max(axis=1)))


def _log_heldout(rec: rr.RecordingStream, robot: Robot, before: np.ndarray, after: np.ndarray) -> None:
    """Held-out errors (``before``, ``after``: (M, D), mm and rad) as norms per held-out pose on
    the ``pose`` timeline (numbered within their own set): position in um, orientation in urad."""
    angle = robot.angle_pose_mask
    pos = ~angle
    hb = np.linalg.norm(before[:, pos], axis=1) * 1e3
    ha = np.linalg.norm(after[:, pos], axis=1) * 1e3
    grey, blue = MACHINE_COLORS["nominal"], MACHINE_COLORS["calibrated"]
    log_series_by_pose(rec, "heldout/position_error_um", np.c_[hb, ha],
                       ["before (nominal commands)", "after (compensated)"], [grey, blue])
    if angle.any():
        ob = np.linalg.norm(before[:, angle], axis=1) * 1e6
        oa = np.linalg.norm(after[:, angle], axis=1) * 1e6
        log_series_by_pose(rec, "heldout/orientation_error_urad", np.c_[ob, oa],
                           ["before (nominal commands)", "after (compensated)"], [grey, blue])


def _log_convergence(rec: rr.RecordingStream, history, history_label: str) -> None:
    """``history`` (per iteration) as a static log chart (any timeline) and on the ``iteration`` timeline."""
    hist = np.asarray(history, dtype=float)
    if hist.size:
        it = np.arange(1, hist.size + 1)
        log_plot(rec, "convergence/chart", [(history_label, it, hist, (240, 200, 60))], x_label="iteration",
                 y_label=history_label, log_y=True, width=340.0, height=150.0)
        with np.errstate(divide="ignore"):
            rec.send_columns("convergence/log10", indexes=[rr.TimeColumn("iteration", sequence=it)],
                             columns=rr.Scalars.columns(scalars=np.log10(hist)))


def _log_parameter_bars(rec: rr.RecordingStream, robot: Robot, nominal: np.ndarray, actual: np.ndarray | None,
                        identified: np.ndarray, std: np.ndarray, chains: list[str]) -> None:
    """Parameters by name: identified - nominal (+-2 ``std``) beside injected, one scale (um;
    angles as arcs, :func:`_bar_unit`). The vectors are (P,) in the parameters' units."""
    to_um, has_angles = _bar_unit(robot)
    series = [("identified", to_um * (identified - nominal), MACHINE_COLORS["calibrated"])]
    if actual is not None:
        series.append(("injected", to_um * (actual - nominal), MACHINE_COLORS["actual"]))
    note = (f"angles drawn as the arc they make at {robot.length_scale_mm:.0f} mm (1 urad = "
            f"{robot.length_scale_mm / 1e3:.3g} um)") if has_angles else ""
    log_named_bars(rec, "parameters/chart", list(robot.table.names), series, unit="um", sigma=to_um * std,
                   groups=[p.chain for p in robot.table], group_names=chains, title="identified - nominal",
                   note=note, rows_per_column=48)


def log_calibration_run(
    rec: rr.RecordingStream, *, robot: Robot, nominal: np.ndarray, actual: np.ndarray | None,
    identified: np.ndarray, std: np.ndarray, joints: np.ndarray, targets: np.ndarray, measured: np.ndarray,
    predicted: np.ndarray, history, heldout_before: np.ndarray | None,
    heldout_after: np.ndarray | None, summary_markdown: str, observability=None, flagged=(),
    history_label: str = "max dQint", magnified: float | None = None,
) -> None:
    """Log one calibration run (see the module docstring for the entities).

    Args:
        rec: the recording stream.
        robot: the robot.
        nominal, actual, identified: (P,) parameter vectors (``actual`` None for a real machine).
        std: (P,) standard uncertainty of the identified parameters.
        joints: (N, C) commanded joints of the calibration poses.
        targets: (N, D) poses the controller intended.
        measured: (N, D) measured poses.
        predicted: (N, D) poses the identified model predicts at the commanded joints.
        history: max dQint (or cost) per iteration.
        heldout_before, heldout_after: (M, D) held-out pose errors (reached - target), or None.
        summary_markdown: text of the summary panel (the run's report as markdown,
            :func:`pipeline.report.text.report_markdown`).
        observability: a :class:`calib.observability.ObservabilityAnalysis` to log, or None.
        flagged: 0-based indices of the calibration poses flagged as outliers.
        history_label: what ``history`` holds.
        magnified: factor of the drawn departures from nominal (default :func:`run_magnification`).
    """
    chains = [f"{robot.chain_word} {i + 1}" for i in range(joints.shape[1])]
    flagged = [int(i) for i in flagged]
    m = magnified if magnified is not None else run_magnification(robot, nominal, actual, identified, targets,
                                                                  measured)
    drawn = actual if actual is not None else identified
    n = len(joints)
    shown = drawn_poses(n)
    size = _log_machines(rec, robot, (nominal, drawn, identified), joints[shown], targets[shown], measured[shown],
                         predicted[shown], m, chains, shown)
    vmax = _log_pose_errors(rec, robot, targets, measured, predicted, m, size, flagged, shown)
    words = "" if shown.size == n else (f"Machines and arrows drawn at {shown.size:,} evenly spaced poses of the "
                                        f"{n:,} ({n:,} > MAX_MACHINE_POSES = {MAX_MACHINE_POSES}).")
    _log_key(rec, robot, m, vmax, simulated=actual is not None, flagged=bool(flagged), drawn=words)
    _log_residuals(rec, robot, nominal, identified, joints, measured, chains, flagged)
    if heldout_before is not None and heldout_after is not None:
        _log_heldout(rec, robot, heldout_before, heldout_after)
    _log_convergence(rec, history, history_label)
    _log_parameter_bars(rec, robot, nominal, actual, identified, std, chains)
    if observability is not None:
        log_observability(rec, observability, "observability", title="Observability of the calibration poses")
    rec.log("summary", rr.TextDocument(summary_markdown, media_type=rr.MediaType.MARKDOWN), static=True)


def run_magnification(robot: Robot, nominal, actual, identified, targets, measured) -> float:
    """The factor a run draws departures from nominal with (:func:`magnification`)."""
    nom = _scene(robot, nominal, targets)
    pos = ~robot.angle_pose_mask
    dep = float(np.abs((measured - targets)[:, pos]).max()) if len(targets) else 0.0
    theta = actual if actual is not None else identified
    dep = max(dep, float(np.abs(robot.chain_points(theta, robot.inverse_kinematics(nominal, targets), targets)
                                - nom).max()))
    return magnification(dep, float(np.ptp(nom.reshape(-1, 3), axis=0).max()))


def run_eye(robot: Robot, nominal, targets) -> rrb.EyeControls3D:
    """The run view's camera: frames the nominal machine at every calibration pose."""
    return _eye(_scene(robot, nominal, targets).reshape(-1, 3))


