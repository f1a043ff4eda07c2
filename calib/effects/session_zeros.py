"""``session_zeros``: the machine re-homed between sessions: from the start of each later session
every joint's zero sits a constant step away from the first session's (a homing switch's
repeatability, an encoder re-zeroed, a spool re-wound).

Not in the registry: its coefficients are one per joint *and per later session*, so it exists only
for a recording of several sessions, built for it (:func:`session_zeros_effect`, as a law is built
for its recording). The discovery adds it to the candidates where the rows it analyses span several
sessions; where a session has only validation rows its shift is found in the held-out residuals
instead (:mod:`calib.effects.heldout`, :mod:`calib.session_shift`). The instrument frame's shift of
a session with calibration rows is fitted by the measured fit (each session its own frame).
"""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect

__all__ = ["SessionZeros", "session_zeros_effect", "SESSION_ZEROS_NAME", "session_codes"]

#: The effect's name.
SESSION_ZEROS_NAME = "session_zeros"


def session_codes(sessions: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    """``((N,) int codes, names)``: each row's session numbered in the order of the sessions' first
    rows, and the names in that order."""
    sessions = np.asarray(sessions)
    names, first = np.unique(sessions, return_index=True)
    order = tuple(str(n) for n in names[np.argsort(first)])
    rank = {n: k for k, n in enumerate(order)}
    return np.array([rank[str(s)] for s in sessions], dtype=int), order


class SessionZeros(Effect):
    """``dq_i = d_{s,i}`` for the rows of session ``s`` (``d_{0,i} = 0``: the first session's
    zeros are the geometry's): one step of every joint's zero at the start of each later session.

    Attributes:
        sessions: the recording's session names, in the order of their first rows (the codes of
            :attr:`calib.effects.EffectData.sessions`).
    """

    name = SESSION_ZEROS_NAME
    physics = "the machine re-homed between sessions: each joint's zero moved, the same for every row of a session"
    granularity = "per_chain"  # already one coefficient per chain (and per later session)
    not_compensable = ("a re-homing between sessions, not a property of the machine: re-reference the session "
                       "(a handful of its poses) rather than command around it")

    def __init__(self, sessions: tuple[str, ...]):
        self.sessions = tuple(sessions)

    def coefficients(self, robot):
        return tuple(Coefficient(f"zero.{j}@{s}", robot.joint_unit) for s in self.sessions[1:] for j in robot.joint_names)

    def joint_regressors(self, robot, theta, data, extra=None):
        c = robot.n_chains
        X = np.zeros((data.n, c, c * (len(self.sessions) - 1)))
        if data.sessions is None:
            return X
        for k in range(1, len(self.sessions)):
            rows = data.sessions == k
            for i in range(c):
                X[rows, i, c * (k - 1) + i] = 1.0
        return X

    def zeros(self, coefficients: np.ndarray, robot) -> dict:
        """``{session: (C,) its zeros' move}`` of the later sessions, joint unit."""
        c = robot.n_chains
        return {s: np.asarray(coefficients[c * (k - 1):c * k], dtype=float)
                for k, s in enumerate(self.sessions) if k > 0}

    def machine_settings(self, coefficients, robot, context, extra=None):
        # the re-homing is in the readings, not in the machine: the re-simulation commands each
        # session's joints moved by its zeros (pipeline.workflows.discovery.resimulate)
        return {"options": {}, "effects": {}}

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        raise NotImplementedError("session_zeros is drawn by a recording of several sessions, not by a scenario")


def session_zeros_effect(sessions: tuple[str, ...]) -> SessionZeros:
    """The effect for a recording whose sessions are ``sessions`` (names, in order)."""
    return SessionZeros(tuple(sessions))
