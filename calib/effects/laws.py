"""Proposed laws: when the library of effects leaves a remainder, a law over joint-space terms.

A *term* is a function of one joint's own variables, evaluated for every joint alike: its stroke
(and powers of it), its last move (its size, its sign), time and saturating functions of time
(a grid of time constants), its load (the joint force of the machine's statics under the
platform's weight, :mod:`calib.effects.compliance`), periodic functions of its stroke (a grid of
pitches), extra recorded channels (a temperature ...) and products of two. Each gives a joint
regressor ``(N, C, k)``: the joint displacement per unit constant, joint unit.

A *law* is one formula for every joint, ``dq_i = sum_t c_ti term_t(joint i)``, with each term's
constant shared by the joints or one per joint. It is an :class:`~calib.effects.base.Effect`
(:class:`Law`, name :data:`LAW_NAME`): its per-joint constants are the per-chain form of the
generic granularity mechanism (:class:`calib.effects.granularity.PerChainForm`), so it is fitted
jointly with the geometry and the library's effects like any effect
(:func:`calib.effects.fit_effects`).

The search (:func:`search_law`) runs on the model the library chose, linearised at its fit
(:class:`LawSpace`: whitened remainder and the model's columns, geometry included): greedy,
each step tries every term of the dictionary in both forms (the per-joint form kept only when its
BIC, which charges ``ln n`` per extra constant, is lower: the same evidence as the per-chain forms
of the library), a parametrised term on its grid refined by golden section; a term is kept only
when it lowers the BIC by :data:`LAW_MIN_DELTA_BIC` (the size penalty, with a look-elsewhere
charge for the number of terms tried) and the ``folds``-fold cross-validated residual (closed
form, whole measurements left out) by the margin :data:`LAW_CV_MARGIN`; among those, the lowest
cross-validated residual enters (within the margin of it, the one with the fewest constants).
At most :data:`MAX_LAW_TERMS` terms.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .base import Coefficient, Effect, EffectData, orthonormal_columns
from .compliance import EFFECT as COMPLIANCE
from .granularity import PER_CHAIN, SHARED, PerChainForm
from .periodic_screw_error import EFFECT as SCREW
from .thermal_warmup import TAU_RANGE_SPANS

if TYPE_CHECKING:  # the remainder's room loads scipy.stats, which reading a kept law does not need
    from .remainder import Remaining

__all__ = ["LAW_NAME", "LAW_WORDS", "MAX_LAW_TERMS", "LAW_MIN_DELTA_BIC", "LAW_NESTED_DELTA_BIC", "LAW_CV_MARGIN", "LAW_TAU_POINTS",
           "Term", "TermFamily", "term_families", "Law", "law_effect", "LawSpace", "LawSearch", "search_law",
           "law_formula", "law_to_dict", "law_from_dict", "joint_quantities", "channels_at", "law_channels",
           "ProposedLaw"]

#: The name of a proposed law as an effect (one at most in a model).
LAW_NAME = "proposed_law"
#: What a proposed law is said to be, in every report.
LAW_WORDS = "proposed law, not in the library"
#: Most terms in one law.
MAX_LAW_TERMS = 3
#: Evidence a term needs to enter: its BIC drop (chi-square drop, scaled by the remainder's
#: reduced chi-square when above 1, minus ``ln n`` per constant) at least this plus ``2 ln M``
#: for the ``M`` candidates tried at the step (the best of ``M`` chance gains grows as ``2 ln M``).
LAW_MIN_DELTA_BIC = 10.0
#: A term must lower the cross-validated whitened RMS by at least this fraction of it.
LAW_CV_MARGIN = 0.01
#: Grid points of a saturating term's time constant (log grid over
#: :data:`calib.effects.thermal_warmup.TAU_RANGE_SPANS` times the recording's last time).
LAW_TAU_POINTS = 12
#: Evidence a saturating term ``(1 - exp(-t/T)) * x`` needs over its long-time-constant limit
#: ``x * t`` (nested: the limit is named unless the saturation gains this much BIC; the library's
#: :data:`calib.effects.selection.MIN_NESTED_DELTA_BIC` for a warm-up over a drift).
LAW_NESTED_DELTA_BIC = 10.0
#: Golden-section iterations refining a parametrised term between its grid neighbours.
REFINE_ITERATIONS = 25


# ----------------------------------------------------------------------------- the dictionary


def joint_quantities(data: EffectData, channels: dict | None = None) -> dict:
    """``{name: (N, C)}``: each joint's own variables the terms are made of (joint unit, s, the
    load per unit platform weight, recorded channels broadcast to every joint)."""
    robot = data.robot
    n, c = data.n, robot.n_chains
    q = {"stroke": data.stroke, "last move": data.last_move, "|last move|": np.abs(data.last_move),
         "sign(last move)": data.direction, "t": np.broadcast_to(data.t_s[:, None], (n, c))}
    if COMPLIANCE.applies_to(robot):
        q["load"] = COMPLIANCE.joint_regressors(robot, data.theta, data)[..., 0]
    for name, v in (channels or {}).items():
        v = np.asarray(v, dtype=float)
        q[name] = np.broadcast_to(v[:, None] if v.ndim == 1 else v, (n, c))
    return q


@dataclass(frozen=True)
class TermFamily:
    """A term, or a family of terms with one parameter found by search.

    Attributes:
        key: the family's name (``"1 - exp(-t/T)"``, ``"last move"``, ``"sign(last move) * t"``).
        parts: the quantities it multiplies (:func:`joint_quantities` names), empty for none.
        kind: ``"product"`` (the parts multiplied), ``"power"`` (the one part to ``power``),
            ``"saturating"`` (``1 - exp(-t / T)`` times the parts), ``"periodic"`` (sin and cos of
            ``2 pi stroke / p``).
        power: the power of a ``"power"`` term.
        unit: the unit of the term's value (its constant's is the joint unit over it).
    """

    key: str
    parts: tuple = ()
    kind: str = "product"
    power: int = 1
    unit: str = "1"

    @property
    def searched(self) -> bool:
        return self.kind in ("saturating", "periodic")

    def grid(self, data: EffectData) -> np.ndarray:
        """The search coordinate's grid: ``log T`` or ``1 / p``."""
        if self.kind == "saturating":
            span = max(float(np.max(data.t_s)), 1e-9)
            return np.linspace(np.log(TAU_RANGE_SPANS[0] * span), np.log(TAU_RANGE_SPANS[1] * span), LAW_TAU_POINTS)
        return SCREW.search_grid(data)

    def value(self, u: float) -> float:
        """The parameter (T in s, p in the joint unit) at search coordinate ``u``."""
        return float(np.exp(u)) if self.kind == "saturating" else float(1.0 / u)


@dataclass(frozen=True)
class Term:
    """A term of a law: its family and its parameter (None for an unparametrised one)."""

    family: TermFamily
    param: float | None = None

    @property
    def name(self) -> str:
        f = self.family
        if f.kind == "saturating":
            base = f"(1 - exp(-t/{self.param:.4g} s))"
            return " * ".join((base,) + f.parts) if f.parts else base[1:-1]
        if f.kind == "periodic":
            return f"periodic(stroke, pitch {self.param:.4g})"
        return f.key

    def column_names(self) -> tuple[str, ...]:
        if self.family.kind == "periodic":
            return (f"sin(2 pi stroke/{self.param:.4g})", f"cos(2 pi stroke/{self.param:.4g})")
        return (self.name,)

    def regressor(self, q: dict) -> np.ndarray:
        """(N, C, k) the term's value for every joint."""
        f = self.family
        if f.kind == "periodic":
            phase = 2 * np.pi * q["stroke"] / self.param
            return np.stack([np.sin(phase), np.cos(phase)], axis=-1)
        if f.kind == "power":
            return (q[f.parts[0]] ** f.power)[..., None]
        v = np.ones_like(q["t"], dtype=float)
        for p in f.parts:
            v = v * q[p]
        if f.kind == "saturating":
            v = v * -np.expm1(-q["t"] / self.param)
        return v[..., None]


def _unit(parts: tuple, units: dict) -> str:
    us = [units[p] for p in parts if units[p] != "1"]
    return " ".join(us) or "1"


def term_families(data: EffectData, channels: dict | None = None) -> list[TermFamily]:
    """The dictionary on ``data``'s robot: every single quantity, the powers of the stroke, the
    saturating function of time (alone and times each motion or load quantity), the periodic
    functions of the stroke (where the joints are lengths: a screw), and products of two."""
    robot = data.robot
    ju = robot.joint_unit
    q = joint_quantities(data, channels)
    units = {"stroke": ju, "last move": ju, "|last move|": ju, "sign(last move)": "1", "t": "s", "load": "1"}
    units.update({k: "channel unit" for k in (channels or {})})
    singles = [k for k in q]
    fams = [TermFamily(k, (k,), unit=units[k]) for k in singles]
    fams += [TermFamily(f"stroke^{p}", ("stroke",), "power", p, f"{ju}^{p}") for p in (2, 3)]
    fams.append(TermFamily("1 - exp(-t/T)", (), "saturating"))
    fams += [TermFamily(f"(1 - exp(-t/T)) * {k}", (k,), "saturating", unit=units[k]) for k in singles if k != "t"]
    if SCREW.applies_to(robot):
        fams.append(TermFamily("periodic(stroke, pitch p)", ("stroke",), "periodic"))
    redundant = {frozenset(("sign(last move)", "|last move|"))}  # their product is the last move
    for i, a in enumerate(singles):
        for b in singles[i + 1:]:
            if frozenset((a, b)) not in redundant:
                fams.append(TermFamily(f"{a} * {b}", (a, b), unit=_unit((a, b), units)))
    return fams


# ----------------------------------------------------------------------------- the law as an effect


def _constant_unit(joint_unit: str, term_unit: str) -> str:
    if term_unit == "1":
        return joint_unit
    if term_unit == joint_unit:
        return "1"
    return f"{joint_unit}/({term_unit})" if " " in term_unit else f"{joint_unit}/{term_unit}"


class Law(Effect):
    """A proposed law as an effect: ``dq_i = sum_t c_t term_t(joint i)``, shared constants (the
    per-joint ones are :func:`law_effect`'s per-chain form of it)."""

    name = LAW_NAME
    physics = LAW_WORDS
    history_dependent = True

    def __init__(self, terms: tuple, per_chain_terms: tuple = (), channels: dict | None = None,
                 name: str = LAW_NAME, channel_times_s: np.ndarray | None = None):
        self.terms = tuple(terms)
        self.name = name
        self.channels = dict(channels or {})
        self.channel_times_s = None if channel_times_s is None else np.asarray(channel_times_s, dtype=float)
        self.per_chain_capable = tuple(c for t in self.terms if t.name in per_chain_terms for c in t.column_names())

    def coefficients(self, robot):
        ju = robot.joint_unit
        return tuple(Coefficient(c, _constant_unit(ju, t.family.unit)) for t in self.terms for c in t.column_names())

    def joint_regressors(self, robot, theta, data, extra=None):
        q = joint_quantities(data, channels_at(self.channels, self.channel_times_s, data))
        return np.concatenate([t.regressor(q) for t in self.terms], axis=-1)

    def compensation_inputs(self):
        timed = any(t.family.kind == "saturating" or "t" in t.family.parts for t in self.terms)
        return (("t_s",) if timed else ()) + law_channels(self.terms)

    def machine_settings(self, coefficients, robot, context, extra=None):
        raise NotImplementedError("a proposed law has no MuJoCo machine field: it is not in the library")

    def __repr__(self) -> str:
        return f"<{LAW_WORDS}: {' + '.join(t.name for t in self.terms)}>"


def channels_at(channels: dict, times_s: np.ndarray | None, data: EffectData) -> dict:
    """``channels`` at ``data``'s rows: as they are (``times_s`` None: already one value per row),
    or looked up by each row's time in ``times_s`` (the recording's times: a kept law refitted on
    any subset of the rows of the recording whose channels it was given).

    Raises:
        ValueError: a row whose time is not among ``times_s``.
    """
    if times_s is None or not channels:
        return channels
    k = np.clip(np.searchsorted(times_s, data.t_s), 0, times_s.size - 1)
    if not np.allclose(times_s[k], data.t_s, rtol=0, atol=1e-9):
        raise ValueError("a row's time is not among the recorded channels' times")
    return {name: np.asarray(v)[k] for name, v in channels.items()}


def law_effect(terms, granularity: dict, channels: dict | None = None, *, name: str = LAW_NAME,
               channel_times_s: np.ndarray | None = None) -> Effect:
    """The law of ``terms`` with each term's constants ``granularity[term name]`` (``shared`` or
    ``per_chain``): a :class:`Law` called ``name``, or its per-chain form when any term is per
    joint. ``channels`` (recorded channels the terms use) are one value per row of the data it is
    fitted on, or, with ``channel_times_s``, per time of the recording (:func:`channels_at`)."""
    pc = tuple(t.name for t in terms if granularity.get(t.name) == PER_CHAIN)
    law = Law(tuple(terms), pc, channels, name, channel_times_s)
    return PerChainForm(law) if pc else law


def law_formula(terms, granularity: dict, symbol: str = "q", chain_word: str = "chain") -> str:
    """``dq_i = c1_i * last move_i + c2 * t`` in words: ``_i`` marks a constant of each joint."""
    parts = []
    for k, t in enumerate(terms, 1):
        own = "_i" if granularity.get(t.name) == PER_CHAIN else ""
        parts.append(f"c{k}{own} * [{t.name}]")
    return f"d{symbol}_i = " + " + ".join(parts) + f"   (i: the {chain_word}; _i: a constant per {chain_word})"


def law_to_dict(terms, granularity: dict, constants: np.ndarray | None = None) -> dict:
    """A law as JSON-ready data (:func:`law_from_dict` reads it back)."""
    out = {"terms": [{"key": t.family.key, "parts": list(t.family.parts), "kind": t.family.kind,
                      "power": t.family.power, "unit": t.family.unit, "param": t.param,
                      "granularity": granularity.get(t.name, SHARED)} for t in terms]}
    if constants is not None:
        out["constants"] = np.asarray(constants, dtype=float).tolist()
    return out


def law_channels(terms) -> tuple[str, ...]:
    """The recorded channels ``terms`` use (the quantities that are not each joint's own)."""
    own = {"stroke", "last move", "|last move|", "sign(last move)", "t", "load"}
    return tuple(dict.fromkeys(p for t in terms for p in t.family.parts if p not in own))


def law_from_dict(d: dict) -> tuple[tuple, dict]:
    """``(terms, granularity)`` from :func:`law_to_dict`'s data."""
    terms = tuple(Term(TermFamily(e["key"], tuple(e["parts"]), e["kind"], int(e["power"]), e["unit"]), e["param"])
                  for e in d["terms"])
    return terms, {t.name: e["granularity"] for t, e in zip(terms, d["terms"])}


# ----------------------------------------------------------------------------- the search


@dataclass(frozen=True, eq=False)
class LawSpace:
    """The fitted model (geometry and the library's effects) linearised at its solution, where
    the law search runs.

    Attributes:
        data: the measurements.
        winv: (N, C, C) each measurement's whitening (``L^-1``, ``L L^T`` the closure noise
            covariance).
        dF_dq: (N, C, C) the closure's joint Jacobian at the fit.
        design: (N C, p) the fit's whitened derivatives (geometry and effects).
        whitened: (N, C) the fit's whitened residuals.
        channels: extra recorded channels ``{name: (N,) or (N, C)}``.
    """

    data: EffectData
    winv: np.ndarray
    dF_dq: np.ndarray
    design: np.ndarray
    whitened: np.ndarray
    channels: dict = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "M", -self.winv @ self.dF_dq)
        object.__setattr__(self, "L", np.linalg.inv(self.winv))
        object.__setattr__(self, "Q0", orthonormal_columns(self.design))
        object.__setattr__(self, "q", joint_quantities(self.data, self.channels))
        b = self.whitened.ravel()
        object.__setattr__(self, "b", b - self.Q0 @ (self.Q0.T @ b))

    @property
    def n(self) -> int:
        return self.b.size

    @property
    def dof0(self) -> int:
        return self.n - self.Q0.shape[1]

    def columns(self, term: Term, per_chain: bool) -> np.ndarray:
        """(N C, k) or (N C, k C): the term's whitened closure columns, the model projected out."""
        Xq = term.regressor(self.q)
        if per_chain:
            X = (self.M[:, :, :, None] * Xq[:, None, :, :]).reshape(self.data.n, self.M.shape[1], -1)
        else:
            X = self.M @ Xq
        X = X.reshape(self.n, -1)
        return X - self.Q0 @ (self.Q0.T @ X)

    def chi2(self, Qs: np.ndarray, X: np.ndarray | None = None) -> float:
        """Chi-square with the selected columns (orthonormal ``Qs``) and ``X`` fitted too."""
        e = self.b - Qs @ (Qs.T @ self.b)
        if X is None or X.shape[1] == 0:
            return float(e @ e)
        Xp = X - Qs @ (Qs.T @ X)
        Qx = orthonormal_columns(Xp)
        e = e - Qx @ (Qx.T @ e)
        return float(e @ e)

    def cv(self, blocks: list, folds: int, seed: int) -> tuple[float, float]:
        """``(whitened RMS, RMS in mm)`` of the deleted residuals of ``folds``-fold
        cross-validation (whole measurements left out), closed form through the hat matrix."""
        Q = self.Q0 if not blocks else np.hstack([self.Q0, orthonormal_columns(np.hstack(blocks))])
        e = self.b - Q @ (Q.T @ self.b)
        C = self.M.shape[1]
        m = self.n // C
        order = np.random.default_rng(seed).permutation(m)
        ss_w, ss_mm = 0.0, 0.0
        for k in range(folds):
            rows = np.sort(order[k::folds])
            idx = (rows[:, None] * C + np.arange(C)).ravel()
            Qi = Q[idx]
            d = np.linalg.solve(np.eye(idx.size) - Qi @ Qi.T, e[idx])
            ss_w += float(d @ d)
            ss_mm += float(np.sum(np.einsum("nij,nj->ni", self.L[rows], d.reshape(-1, C)) ** 2))
        return float(np.sqrt(ss_w / self.n)), float(np.sqrt(ss_mm / self.n))


def _trial(space: LawSpace, fam: TermFamily, per_chain: bool, Qs: np.ndarray) -> tuple:
    """``(term, columns, chi2, evaluations)``: the family's best term in one form (a parametrised
    one searched on its grid and refined by golden section between the best point's neighbours)."""
    if not fam.searched:
        t = Term(fam)
        X = space.columns(t, per_chain)
        return t, X, space.chi2(Qs, X), 1

    def cost(u):
        t = Term(fam, fam.value(u))
        X = space.columns(t, per_chain)
        return space.chi2(Qs, X), t, X

    grid = fam.grid(space.data)
    costs = [cost(u)[0] for u in grid]
    k = int(np.argmin(costs))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    g = (np.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = cost(c)[0], cost(d)[0]
    for _ in range(REFINE_ITERATIONS):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = cost(c)[0]
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = cost(d)[0]
    best = min((cost(grid[k]), cost((a + b) / 2)), key=lambda r: r[0])
    return best[1], best[2], best[0], len(grid) + 2 * REFINE_ITERATIONS + 4


@dataclass
class LawSearch:
    """What :func:`search_law` chose.

    Attributes:
        terms: the terms, in the order they entered.
        granularity: ``{term name: "shared" | "per_chain"}``.
        cv_before, cv_after: cross-validated whitened RMS of the library's model alone and with
            the law (1: the noise).
        cv_before_mm, cv_after_mm: the same residuals in mm.
        steps: per step, the best candidates (name, form, BIC drop, CV) and what entered.
    """

    terms: tuple
    granularity: dict
    cv_before: float
    cv_after: float
    cv_before_mm: float
    cv_after_mm: float
    steps: list


def _step(space: LawSpace, fams: list, Qs: np.ndarray, blocks: list, chi2_cur: float, p_cur: int,
          folds: int, seed: int) -> tuple[list, int]:
    """One greedy step: every family's best term in its form by BIC (per-joint only when its BIC
    is lower); returns ``(trials, candidates evaluated)``, each trial with its BIC drop and, when
    it passes the evidence bar, its cross-validated residual."""
    log_n = np.log(space.n)
    trials, m = [], 0
    for fam in fams:
        forms = []
        for per_chain in (False, True):
            t, X, chi2_new, evals = _trial(space, fam, per_chain, Qs)
            m += evals
            k = X.shape[1] + fam.searched
            s2 = max(1.0, chi2_new / max(space.dof0 - p_cur - k, 1))
            forms.append({"term": t, "X": X, "k": k, "chi2": chi2_new, "form": PER_CHAIN if per_chain else SHARED,
                          "delta_bic": (chi2_cur - chi2_new) / s2 - k * log_n})
        trials.append(max(forms, key=lambda f: f["delta_bic"]))  # ties: the shared form (first)
    bar = LAW_MIN_DELTA_BIC + 2 * np.log(max(m, 1))
    for t in trials:
        t["passes"] = bool(t["delta_bic"] >= bar)
        if t["passes"]:
            t["cv"] = space.cv(blocks + [t["X"]], folds, seed)
    return trials, m


def _linear_limit(fam: TermFamily, fams: list) -> TermFamily | None:
    """The family a saturating ``fam`` tends to as its time constant grows (its parts times
    ``t``), or None."""
    if fam.kind != "saturating":
        return None
    want = set(fam.parts) | {"t"}
    return next((f for f in fams if f.kind == "product" and set(f.parts) == want and len(f.parts) == len(want)), None)


def _preferred(ok: list):
    """The lowest cross-validated residual; among the terms within :data:`LAW_CV_MARGIN` of it,
    the one with the fewest constants (a time constant or pitch counted), then the lowest
    residual: a slow saturation is not named where a straight line in time does as well. A
    saturating term whose linear limit also passes is dropped unless its BIC is ahead of it by
    :data:`LAW_NESTED_DELTA_BIC` (nested models: the simpler is named)."""
    fams = [t["term"].family for t in ok]
    by_family = {t["term"].family: t for t in ok}
    ok = [t for t in ok if (lim := _linear_limit(t["term"].family, fams)) is None
          or t["delta_bic"] - by_family[lim]["delta_bic"] >= LAW_NESTED_DELTA_BIC]
    if not ok:
        return None
    low = min(t["cv"][0] for t in ok)
    near = [t for t in ok if t["cv"][0] <= (1 + LAW_CV_MARGIN) * low]
    return min(near, key=lambda t: (t["k"], t["cv"][0]))


def search_law(space: LawSpace, *, folds: int = 5, seed: int = 0, max_terms: int = MAX_LAW_TERMS,
               families: list | None = None) -> LawSearch:
    """Greedy search of a law over the dictionary (see the module docstring).

    Args:
        space: the library's fitted model, linearised.
        folds, seed: the cross-validation.
        max_terms: most terms.
        families: the dictionary (default :func:`term_families` of ``space.data``).
    """
    fams = list(families if families is not None else term_families(space.data, space.channels))
    blocks, terms, gran, steps = [], [], {}, []
    Qs = np.zeros((space.n, 0))
    chi2_cur, p_cur = space.chi2(Qs), 0
    cv0 = space.cv([], folds, seed)
    cv_cur = cv0
    while len(terms) < max_terms:
        used = {t.family.key for t in terms}
        trials, m = _step(space, [f for f in fams if f.key not in used], Qs, blocks, chi2_cur, p_cur, folds, seed)
        ok = [t for t in trials if t["passes"] and t["cv"][0] <= (1 - LAW_CV_MARGIN) * cv_cur[0]]
        best = _preferred(ok)
        top = sorted(trials, key=lambda t: -t["delta_bic"])[:5]
        steps.append({"candidates": m, "bar": LAW_MIN_DELTA_BIC + 2 * np.log(max(m, 1)),
                      "best": [{"term": t["term"].name, "form": t["form"], "delta_bic": float(t["delta_bic"]),
                                "cv_whitened_rms": t["cv"][0] if "cv" in t else None} for t in top],
                      "added": None if best is None else best["term"].name})
        if best is None:
            break
        terms.append(best["term"])
        gran[best["term"].name] = best["form"]
        blocks.append(best["X"])
        Qs = orthonormal_columns(np.hstack(blocks))
        chi2_cur, p_cur, cv_cur = best["chi2"], p_cur + best["k"], best["cv"]
    return LawSearch(tuple(terms), gran, cv0[0], cv_cur[0], cv0[1], cv_cur[1], steps)


@dataclass(frozen=True, eq=False)
class ProposedLaw:
    """A law found where the library left a remainder, fitted exactly with the library's model.

    Attributes:
        search: the search (:class:`LawSearch`).
        effect: the law as an effect (:func:`law_effect`).
        fit: the exact joint fit (geometry, the library's effects and the law; an
            :class:`calib.effects.EffectFit`).
        remaining: the remainder tests' ``remaining`` with the law fitted
            (:func:`calib.effects.remainder_tests`, :class:`calib.effects.remainder.Remaining`).
        noise_floor_mm: RMS of the closure noise's standard deviations, mm.
        cv_after, cv_after_mm: cross-validated residual (whitened, mm) of the exact fit with the
            law (the search's own figure is linearised at the library's fit, which a large
            remainder makes inexact).
        dropped: the library's effects the law leaves nothing to explain, dropped from ``fit``
            when re-examined with the law in (:func:`calib.effects.discovery.reexamined`).
    """

    search: LawSearch
    effect: Effect
    fit: object
    remaining: Remaining
    noise_floor_mm: float
    cv_after: float
    cv_after_mm: float
    dropped: tuple = ()

    def chain_constants(self) -> tuple[np.ndarray, np.ndarray]:
        """``(values, std)``, each (C, k): every constant of the law joint by joint (a shared one
        repeated), in the order of the terms' columns."""
        robot = self.fit.robot
        s = self.fit.slices()[LAW_NAME]
        v, sd = self.fit.coefficients[s], self.fit.coefficient_std[s]
        if isinstance(self.effect, PerChainForm):
            return self.effect.chain_coefficients(v, robot), self.effect.chain_coefficients(sd, robot)
        return np.tile(v, (robot.n_chains, 1)), np.tile(sd, (robot.n_chains, 1))

    def summary(self) -> dict:
        """JSON-ready: the summary's ``proposed_law`` (``terms``, ``constants`` by joint,
        ``cv_rms_before_mm``, ``cv_rms_after_mm``, ``granularity`` and the rest)."""
        robot = self.fit.robot
        terms, gran = self.search.terms, self.search.granularity
        values, std = self.chain_constants()
        base = self.effect.base if isinstance(self.effect, PerChainForm) else self.effect
        coefs = base.coefficients(robot)
        kinds = set(gran.values())
        return {"words": LAW_WORDS, "formula": law_formula(terms, gran, robot.joint_symbol, robot.chain_word),
                "terms": [t.name for t in terms],
                "granularity": kinds.pop() if len(kinds) == 1 else {t.name: gran[t.name] for t in terms},
                "term_granularity": {t.name: gran[t.name] for t in terms},
                "constants": {c.name: values[:, j].tolist() for j, c in enumerate(coefs)},
                "constants_std": {c.name: std[:, j].tolist() for j, c in enumerate(coefs)},
                "units": {c.name: c.unit for c in coefs},
                "constant_granularity": {c: gran[t.name] for t in terms for c in t.column_names()},
                "cv_rms_before_mm": self.search.cv_before_mm, "cv_rms_after_mm": self.cv_after_mm,
                "cv_whitened_rms_before": self.search.cv_before, "cv_whitened_rms_after": self.cv_after,
                "noise_floor_mm": self.noise_floor_mm,
                "explained_with_law": not self.remaining.present, "remaining_with_law": self.remaining.summary,
                "law": law_to_dict(terms, gran, self.fit.coefficients[self.fit.slices()[LAW_NAME]]),
                "library_effects": [m.name for m in self.fit.models if m.name != LAW_NAME],
                "library_effects_dropped": list(self.dropped),
                "steps": self.search.steps}
