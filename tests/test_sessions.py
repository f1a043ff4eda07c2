"""One machine measured in several sessions, each in its own instrument frame (calib.measurement).

Kinematic simulation, every robot: a machine ``theta`` whose free parameters are drawn from the
default prior (``ParameterPrior.default``: normal about the nominal values, the tolerance as
standard deviation: the machine the prior describes), moved to seeded reachable poses by
its inverse kinematics; the instrument reports each pose composed with its session's frame, plus
normal noise of 1 um on every position and 1 urad on every angle (declared as such). Session 0 is
seen from ``F0`` (300 mm away, turned 0.3 rad), session 1 from ``F1 = M o F0``: the instrument
moved by ``M``, 50 mm and a further 0.6 degree.

What is identifiable. The two frames and the base are redundant by one common rigid motion (the
base moved and both frames moved back): the data fix neither frame alone, only the motion between
them, ``F1 o F0^-1 = M``, whatever holds the gauge. With the default prior the prior on the
geometry holds the common motion, and each frame's reported standard deviation includes it (the
machine's true errors, within the tolerance, are a draw the prior allows): each frame is then
compared with its truth too. Without a prior the gauge fixes the common motion (the geometry's
errors without component along it): only ``M`` is compared.
"""

import numpy as np
import pytest
from scipy.stats import chi2

from calib.measurement import identify_measured, instrument_measurements
from calib.noise import SensorNoise
from calib.prior import ParameterPrior
from calib.robots import ROBOTS, default_robot
from calib.rotation import euler_from_matrix, matrix_from_quaternion, rotation_matrix
from calib.workspace import reachable_poses

NOISE = SensorNoise(0.001, 1e-6, "normal")
#: Calibration and held-out poses per session.
N_FIT, N_HELD = 40, 20
#: Recovered within this many of the fit's own standard deviations.
SIGMAS = 4.0
#: False-alarm probability of each chi-square bound (each side).
ALPHA = 1e-3


def _turn(axis, angle):
    """(3,) angles of the rotation by ``angle`` rad about ``axis``."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return euler_from_matrix(matrix_from_quaternion(np.r_[np.cos(angle / 2), np.sin(angle / 2) * a]))


def _then(motion, frame):
    """The frame ``motion o frame``, composed independently of calib.measurement (4x4 matrices)."""
    def matrix(f):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = rotation_matrix(f[3:]), f[:3]
        return T
    T = matrix(motion) @ matrix(frame)
    return np.r_[T[:3, 3], euler_from_matrix(T[:3, :3])]


F0 = np.r_[300.0 * np.array([1.0, 2.0, 2.0]) / 3.0, _turn([1.0, -1.0, 2.0], 0.3)]
#: The instrument's motion between the sessions: 50 mm, 0.6 degree.
MOTION = np.r_[50.0 * np.array([2.0, -1.0, 2.0]) / 3.0, _turn([0.0, 1.0, 1.0], np.radians(0.6))]
F1 = _then(MOTION, F0)


def _two_sessions(name, seed=0):
    """The robot, its true machine, and per session ``(joints, measured)`` for the fit and held out."""
    robot = default_robot(name)
    prior = ParameterPrior.default(robot)
    rng = np.random.default_rng(seed)
    theta = robot.table.nominal.copy()
    idx = np.sort(robot.table.indices(robot.free_default))
    theta[idx] += rng.standard_normal(idx.size) * prior.std[idx]
    out = []
    for s, frame in enumerate((F0, F1)):
        poses = reachable_poses(robot, N_FIT + N_HELD, 100 * seed + s, theta=theta)
        q = robot.inverse_kinematics(theta, poses)
        m = instrument_measurements(robot, poses, frame) + NOISE.sample(len(q), 100 * seed + 10 + s, robot.pose_units)
        out.append(((q[:N_FIT], m[:N_FIT]), (q[N_FIT:], m[N_FIT:])))
    return robot, prior, theta, out


def _stacked(parts):
    q = np.concatenate([p[0] for p in parts])
    m = np.concatenate([p[1] for p in parts])
    return q, m, np.repeat(np.arange(len(parts)), [len(p[0]) for p in parts])


def _assert_motion_recovered(fit):
    motion, std = fit.session_motion(1, 0)
    err = motion - MOTION
    assert np.all(std > 0)
    assert np.all(np.abs(err) <= SIGMAS * std), (err, std)
    return err, std


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_two_sessions_recover_both_frames_and_predict_held_out_rows_at_the_noise(name):
    robot, prior, theta, data = _two_sessions(name)
    q, m, sessions = _stacked([d[0] for d in data])
    fit = identify_measured(robot, q, m, NOISE, frame="estimate", prior=prior, sessions=sessions)
    assert fit.result.success and fit.n_sessions == 2 and fit.frames_estimated.all()
    # the prior's rows hold the geometry (as many rows as unknowns); the frames take 6 a session
    lo, hi = chi2.ppf([ALPHA, 1 - ALPHA], m.size - 6 * fit.n_sessions)
    assert lo <= fit.result.chi2 <= hi, fit.result.message
    _assert_motion_recovered(fit)
    for frame, got, std in zip((F0, F1), fit.frames, fit.frames_std):  # the prior holds the common motion
        assert np.all(np.abs(got - frame) <= SIGMAS * std), (got - frame, std)
    # held-out rows of each session, predicted in that session's frame
    qv, mv, sv = _stacked([d[1] for d in data])
    r = mv - fit.predict(qv, sessions=sv)
    cov = fit.prediction_covariance(qv, sessions=sv) + np.diag(NOISE.pose_std(robot.pose_units) ** 2)
    w = np.linalg.solve(np.linalg.cholesky(cov), r[:, :, None])[:, :, 0]
    dof = w.size
    lo, hi = chi2.ppf([ALPHA, 1 - ALPHA], dof)
    assert lo <= float(np.sum(w ** 2)) <= hi, np.sqrt(np.mean(w ** 2))
    # the data in the base frame: both sessions' poses agree with the model's
    base = fit.base_poses(qv, mv, sessions=sv)
    np.testing.assert_allclose(fit.to_base(mv, sessions=sv), base)
    np.testing.assert_allclose(robot.forward_kinematics(fit.result.theta, qv), base,
                               atol=SIGMAS * 10 * NOISE.position_mm)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_without_a_prior_the_motion_between_sessions_is_recovered(name):
    robot, _, _, data = _two_sessions(name, seed=1)
    q, m, sessions = _stacked([d[0] for d in data])
    fit = identify_measured(robot, q, m, NOISE, frame="estimate", sessions=sessions)
    assert fit.result.success
    lo, hi = chi2.ppf([ALPHA, 1 - ALPHA], fit.result.dof)
    assert lo <= fit.result.chi2 <= hi, fit.result.message
    _assert_motion_recovered(fit)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_one_frame_for_two_sessions_misfits(name):
    robot, prior, _, data = _two_sessions(name)
    q, m, _ = _stacked([d[0] for d in data])
    fit = identify_measured(robot, q, m, NOISE, frame="estimate", prior=prior)
    assert fit.result.chi2 > chi2.ppf(1 - ALPHA, fit.result.dof), fit.result.message
    assert "does not fit to the declared noise" in fit.result.message or not fit.result.success


def test_one_session_is_the_fit_without_sessions():
    robot, prior, _, data = _two_sessions("hexapod")
    q, m = data[0][0]
    plain = identify_measured(robot, q, m, NOISE, prior=prior)
    named = identify_measured(robot, q, m, NOISE, prior=prior, sessions=np.zeros(len(q), int))
    for a, b in [(plain.result.theta, named.result.theta), (plain.frame, named.frame),
                 (plain.result.covariance, named.result.covariance), (plain.frames, named.frames),
                 (plain.frame[None], named.frames), (plain.frame_std[None], named.frames_std)]:
        np.testing.assert_array_equal(a, b)
    qv, mv = data[0][1]
    np.testing.assert_array_equal(plain.predict(qv), named.predict(qv, sessions=0))
    np.testing.assert_array_equal(plain.to_base(mv), named.to_base(mv, sessions=np.zeros(len(mv), int)))
    assert plain.frames_dict() == {0: plain.frame_dict()}


def test_a_fit_of_several_sessions_does_not_guess_the_session():
    robot, prior, _, data = _two_sessions("hexapod")
    q, m, sessions = _stacked([d[0] for d in data])
    fit = identify_measured(robot, q, m, NOISE, frame="estimate", prior=prior, sessions=sessions)
    with pytest.raises(ValueError, match="sessions="):
        fit.predict(q)
    with pytest.raises(ValueError, match="0..1"):
        fit.to_base(m, sessions=np.full(len(m), 2))
    with pytest.raises(ValueError, match="session 1 has no rows"):
        identify_measured(robot, q, m, NOISE, prior=prior, sessions=np.where(sessions == 1, 2, 0))


def test_each_session_has_its_own_frame_mode():
    """Session 0 in the base frame ("base"), session 1 seen from ``F1`` ("auto" detects it): the
    base session anchors the base, so no gauge is left and ``F1`` itself is identifiable."""
    robot, prior, theta, data = _two_sessions("hexapod", seed=2)
    (q0, m0), _ = data[0]
    poses0 = robot.forward_kinematics(theta, q0)
    m0 = instrument_measurements(robot, poses0, None) + NOISE.sample(len(q0), 7, robot.pose_units)
    q, m, sessions = _stacked([(q0, m0), data[1][0]])
    fit = identify_measured(robot, q, m, NOISE, frame=["base", "auto"], initial_frame=[None, None], sessions=sessions)
    assert fit.frames_estimated.tolist() == [False, True] and fit.gauge == ()
    assert fit.registrations[0] is None and fit.registrations[1] is not None
    np.testing.assert_array_equal(fit.frames[0], np.zeros(6))
    assert np.all(np.abs(fit.frames[1] - F1) <= SIGMAS * fit.frames_std[1]), (fit.frames[1] - F1, fit.frames_std[1])
