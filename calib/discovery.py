"""The discovery policy: from a recording's rows to the physics its geometric model left out,
judged by held-out rows, and the :class:`~calib.calibration.Calibration` it found, in one call
(:func:`discover_machine`; the identification policy's counterpart, :func:`calib.identification.calibrate`).

The steps, in order:

1. **Rows** (:func:`analysed_rows`): the calibration rows and the validation rows, less the rows
   left out (a run's gross rows); where the calibration rows alone are fewer than discovery needs
   (:data:`calib.effects.discovery.MIN_ROWS`), every row, and no validation rows. Rows that never
   move the machine are refused (:class:`MotionlessRows`): no geometry, so no physics, to tell
   from one pose.
2. **Candidates**: the library's (or those given), a kept law, and where the rows analysed span
   several sessions, each later session's re-homing (:func:`calib.effects.session_zeros.session_zeros_effect`).
3. **Discovery** (:func:`calib.effects.discover_effects`) on the rows analysed, with the machine's
   tolerance as the geometry's prior.
4. **Held-out judgement** (:func:`calib.effects.heldout.judge_effects`): the validation rows, or
   folds at random, in blocks of time and by session; where they reject an effect (or the
   separability screen set it aside) the discovery is run again without it, and judged again
   (:data:`MAX_REDISCOVERIES` times at most, the last with the geometry alone); a proposed law is
   judged as an effect is.

A second witness may still reject what the held-out rows kept (the MuJoCo re-simulation, which is
pipeline's): :meth:`DiscoveryOutcome.geometry_alone` is then the discovery with the geometry alone.
:meth:`DiscoveryOutcome.calibration` is what the discovery found, as a calibration file holds it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .calibration import Calibration, validity_domain
from .effects import EffectData, discover_effects, effect as registered_effect, effects_for
from .effects.base import PAYLOAD_CHANNEL
from .effects.discovery import MIN_ROWS, Discovery
from .effects.heldout import TIME_BLOCKS, HeldoutJudgement, heldout_folds, judge_effects
from .effects.records import EffectRecord, fitted_effects
from .effects.separability import GRAM_MIN_RESIDUALS
from .effects.session_zeros import SessionZeros, session_codes, session_zeros_effect
from .diagnosis import motionless_rows
from .noise import SensorNoise
from .prior import ParameterPrior
from .robot import Robot

__all__ = ["MotionlessRows", "DiscoveryRows", "DiscoveryOutcome", "discover_machine", "analysed_rows",
           "MAX_REDISCOVERIES", "HELDOUT_FRACTION"]

#: How many times a discovery is run again without the effects the held-out rows rejected (the
#: last time with the geometry alone).
MAX_REDISCOVERIES = 3
#: Rows held out at random when the recording has no validation rows.
HELDOUT_FRACTION = 0.25


class MotionlessRows(ValueError):
    """The rows analysed never move the machine (:func:`calib.diagnosis.motionless_rows`):
    ``rows`` of them at one pose."""

    def __init__(self, rows: int):
        super().__init__(f"{rows} rows at one pose: nothing to discover")
        self.rows = rows


@dataclass(frozen=True, eq=False)
class DiscoveryRows:
    """A recording's rows as discovery takes them (:func:`discover_machine`'s arguments, checked).

    Attributes:
        robot: the robot.
        joints: (N, C) every row's joints; measured: (N, D) its measured pose, base frame (mm, rad);
            t_s: (N,) its time, s.
        noise: the declared noise.
        sets: (N,) ``calibration`` or ``validation``.
        sessions: (N,) each row's session name.
        extras: ``{name: (N,)}`` recorded channels (a temperature, the payload) a law may use.
    """

    robot: Robot
    joints: np.ndarray
    measured: np.ndarray
    t_s: np.ndarray
    noise: SensorNoise
    sets: np.ndarray
    sessions: np.ndarray
    extras: dict

    def channels(self, rows: np.ndarray) -> dict | None:
        """The recorded channels at ``rows`` (None: none recorded)."""
        return {k: v[rows] for k, v in self.extras.items()} or None


@dataclass(frozen=True, eq=False)
class DiscoveryOutcome:
    """What :func:`discover_machine` found.

    Attributes:
        discovery: the discovery the held-out rows judged (its ``kept`` and ``flagged`` index the
            recording's rows).
        judgement: the held-out judgement (:class:`calib.effects.heldout.HeldoutJudgement`), with
            every effect rejected on the way.
        basis: the held-out rows in words.
        rows: the recording's rows (:class:`DiscoveryRows`).
        data: every row as the effects' data (the machine's tolerance as the prior).
        analysed: the rows analysed (0-based); validation: the validation rows judging them.
        analysed_all: every row was analysed (too few calibration rows alone).
        candidates: the candidate effects (the library's, a kept law, a re-homing).
        names: the candidates' names as given (the summary's).
        seed: seed of the held-out split and of the cross-validation folds.
    """

    discovery: Discovery
    judgement: HeldoutJudgement
    basis: str
    rows: DiscoveryRows
    data: EffectData
    analysed: np.ndarray
    validation: np.ndarray
    analysed_all: bool
    candidates: tuple
    names: tuple
    seed: int

    def rediscovered(self, candidates) -> Discovery:
        """The discovery on the same rows with ``candidates`` (rows indexed as the recording's)."""
        return rediscovered(self.data, self.rows, self.analysed, candidates, self.seed)

    def geometry_alone(self, rejected: tuple) -> "DiscoveryOutcome":
        """The discovery with the geometry alone, judged on the first fold, where a later witness
        rejected the effects named (``rejected``: :class:`calib.effects.heldout.RejectedEffect`,
        reported after those the held-out rows rejected)."""
        geometry = self.rediscovered([])
        again = judge_effects(self.data, geometry.chosen, [self.judgement.fold], self.rows.sessions)
        return replace(self, discovery=geometry,
                       judgement=replace(again, rejected=self.judgement.rejected + tuple(rejected)))

    def calibration(self, *, frames: dict, frames_std: dict, recording: dict,
                    produced_by: str = "pipeline.discover") -> Calibration:
        """What the discovery found, as a calibration file holds it: the geometry fitted jointly
        with the effects named (and the proposed law, when one is), the effects with their
        coefficients (a re-homing left out: it is re-referenced), the instrument ``frames``
        (``{session: (6,)}``) and their ``frames_std`` the read registered, the domain of the rows
        analysed, the declared noise, the ``recording`` it came from."""
        disc = self.discovery
        fit = disc.chosen if disc.proposed_law is None else disc.proposed_law.fit
        robot, rec = self.rows.robot, self.rows
        cov = fit.geometry_covariance()
        free = tuple(robot.free_default)
        idx = robot.table.indices(free)
        rows = disc.kept
        payload = rec.extras.get(PAYLOAD_CHANNEL)
        reference = None if payload is None else float(np.mean(payload[rows]))  # a compliance at several payloads
        return Calibration(robot=robot, theta=fit.theta, std=np.sqrt(np.clip(np.diag(cov), 0.0, None)), free=free,
                           covariance=cov[np.ix_(idx, idx)], frames=frames, frames_std=frames_std,
                           effects=tuple(EffectRecord.from_fitted(fe, robot, reference) for fe in fitted_effects(fit)
                                         if not isinstance(fe.effect, SessionZeros)),
                           validity=validity_domain(robot, rec.measured[rows], rec.joints[rows], rec.t_s[rows]),
                           noise=rec.noise, recording=recording, produced_by=produced_by)


def analysed_rows(sets: np.ndarray, exclude) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(rows analysed, validation rows, whether every row is analysed)``: the calibration rows
    and the validation rows less ``exclude``; where the calibration rows alone are fewer than
    discovery needs, every row (the validation rows then none)."""
    cal = np.flatnonzero(sets == "calibration")
    val = np.flatnonzero(sets == "validation")
    exclude = np.asarray(exclude, dtype=int)
    cal, val = np.setdiff1d(cal, exclude), np.setdiff1d(val, exclude)
    analysed_all = cal.size < MIN_ROWS <= len(sets) - exclude.size
    if analysed_all:  # too few calibration rows alone: every measured row is evidence of the physics
        cal, val = np.setdiff1d(np.arange(len(sets)), exclude), np.zeros(0, dtype=int)
    return cal, val, analysed_all


def rediscovered(data: EffectData, rows: DiscoveryRows, cal: np.ndarray, candidates, seed: int) -> Discovery:
    """The discovery on the rows ``cal`` with ``candidates`` (rows indexed as the recording's)."""
    again = discover_effects(data.subset(cal), candidates=candidates, seed=seed, channels=rows.channels(cal))
    return replace(again, kept=cal[again.kept], flagged=tuple(int(cal[i]) for i in again.flagged))


def discover_machine(rows: DiscoveryRows, *, tolerance: ParameterPrior, seed: int = 0,
                     heldout_fraction: float = HELDOUT_FRACTION, candidates=None, exclude=(),
                     kept_law=None) -> DiscoveryOutcome:
    """Run the discovery policy on a recording's rows (see the module docstring).

    Args:
        rows: the recording's rows (:class:`DiscoveryRows`).
        tolerance: the machine's tolerance, the geometry's prior.
        seed: seed of the held-out split and of the cross-validation folds.
        heldout_fraction: rows held out when the recording has no ``validation`` rows.
        candidates: effect names (or :class:`calib.effects.Effect` objects) to consider; default
            every effect that applies to the robot.
        exclude: 0-based rows left out of every fit (the gross rows a run named); the motion
            history still counts them.
        kept_law: a law kept from an earlier recording, as a candidate effect (its constants
            refitted here), or None.

    Raises:
        MotionlessRows: the rows analysed never move the machine.
    """
    robot = rows.robot
    if candidates is None:
        candidates = effects_for(robot)
    if kept_law is not None:
        candidates = list(candidates) + [kept_law]
    names = tuple(registered_effect(c).name for c in candidates)
    cal, val, analysed_all = analysed_rows(rows.sets, exclude)
    still = motionless_rows(robot, rows.joints[cal], rows.noise.joint_std)
    if still is not None:
        raise MotionlessRows(still)
    codes, session_names = session_codes(rows.sessions)
    data = EffectData(robot, robot.table.nominal, rows.joints, rows.measured, rows.t_s, rows.noise,
                      payload_kg=rows.extras.get(PAYLOAD_CHANNEL), tolerance=tolerance.std, sessions=codes)
    if np.unique(codes[cal]).size > 1:  # rows of several sessions analysed: each later one may have re-homed
        candidates = list(candidates) + [session_zeros_effect(session_names)]
    disc = rediscovered(data, rows, cal, candidates, seed)
    disc, judgement, started = judged(data, rows, disc, cal, val, tuple(candidates), seed, heldout_fraction)
    basis = heldout_basis(rows, disc, val, analysed_all, heldout_fraction, seed, started)
    return DiscoveryOutcome(disc, judgement, basis, rows, data, cal, val, analysed_all, tuple(candidates), names, seed)


def judged(data: EffectData, rec: DiscoveryRows, disc: Discovery, cal: np.ndarray, val: np.ndarray, candidates: tuple,
           seed: int, heldout_fraction: float) -> tuple[Discovery, HeldoutJudgement, bool]:
    """``(discovery, judgement, whether the training fits started from every row's geometry)``:
    ``disc`` (on the rows ``cal``) judged by held-out rows (:func:`calib.effects.heldout.judge_effects`:
    the validation rows ``val``, or folds at random, in blocks of time and by session); where the
    held-out rows reject an effect (or the separability screen set it aside), the discovery is run
    again without it (of ``candidates``), and judged again; then the proposed law (:func:`judged_law`)."""
    rejected: list = []
    for round_ in range(MAX_REDISCOVERIES + 1):
        folds = heldout_folds(rec.t_s, rec.sessions, disc.kept, val, random_fraction=heldout_fraction, seed=seed)
        start = disc.geometry.theta if folds[0].train.size * rec.robot.n_chains > GRAM_MIN_RESIDUALS else None
        unseparated = {u.form for u in disc.separation.unseparated} if disc.separation is not None else set()
        delta_bic = {n: disc.evidence.delta_bic_when_added(n) for n in disc.effects}
        judgement = judge_effects(data, disc.chosen, folds, rec.sessions, unseparated=unseparated,
                                  delta_bic=delta_bic, start=start)
        if not judgement.rejected:
            break
        rejected += judgement.rejected
        out = {r.name for r in rejected}
        # the last round: the geometry alone, which the held-out rows cannot reject
        narrowed = [] if round_ == MAX_REDISCOVERIES - 1 else \
            [c for c in candidates if registered_effect(c).name not in out]
        disc = rediscovered(data, rec, cal, narrowed, seed)
    judgement = replace(judgement, rejected=tuple(rejected))
    judgement, disc = judged_law(data, disc, judgement, folds, rec.sessions, start)
    return disc, judgement, start is not None


def heldout_basis(rec: DiscoveryRows, disc: Discovery, val: np.ndarray, analysed_all: bool, heldout_fraction: float,
                  seed: int, started: bool) -> str:
    """The held-out rows in words (the summary's ``heldout_basis``): the validation rows ``val``, or
    the folds (the share held out at random, the blocks of time, the sessions of ``disc``'s rows);
    every row analysed; the training fits started from every row's geometry (``started``)."""
    basis = "recorded validation rows" if val.size else (
        f"{int(round(100 * heldout_fraction))}% of the rows held out at random (seed {seed}) for the figures; every "
        f"effect also judged on {TIME_BLOCKS} contiguous blocks in time"
        + (" and session by session" if len(set(rec.sessions[disc.kept].tolist())) > 1 else ""))
    if analysed_all:
        basis += (f"; every row analysed, calibration and validation alike (the {int((rec.sets == 'calibration').sum())} "
                  f"calibration rows alone are fewer than the {MIN_ROWS} discovery needs)")
    if started:
        basis += (f"; the training rows' geometry fitted from that of every row (above {GRAM_MIN_RESIDUALS:,} "
                  "residuals)")
    return basis


def judged_law(data: EffectData, disc: Discovery, judgement: HeldoutJudgement, folds, sessions, start) -> tuple:
    """A proposed law judged as an effect is (:func:`calib.effects.heldout.judge_effects`): one that
    predicts the held-out rows worse is dropped and reported."""
    law = disc.proposed_law
    if law is None:
        return judgement, disc
    try:
        j = judge_effects(data, law.fit, folds, sessions, start=start)
    except (ValueError, IndexError, np.linalg.LinAlgError):  # a law bound to the analysed rows' channels
        return judgement, disc
    law_name = law.fit.models[-1].name
    dropped = [r for r in j.rejected if r.name == law_name]
    if not dropped:
        return judgement, disc
    return replace(judgement, rejected=judgement.rejected + tuple(dropped)), replace(disc, proposed_law=None)
