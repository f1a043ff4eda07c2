"""A law a discovery proposed, kept (``python -m pipeline.discover --law``) and used on a later
recording (``--use-law``): the file written and read back checked, and the law as one more
candidate effect, its constants refitted (:func:`kept_law_effect`)."""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.formats import Recording, atomic_write, read_json_file

__all__ = ["KEPT_LAW_NAME", "KEPT_LAW_FORMAT", "keep_law", "read_kept_law", "kept_law_effect"]


#: The name a kept law (``--use-law``) has as a candidate effect.
KEPT_LAW_NAME = "kept_law"
#: What a kept law file holds (``--law``): its format's name, written and checked.
KEPT_LAW_FORMAT = "parallel-calib kept law 1"


def keep_law(path: Path, summary: dict, *, overwrite: bool = False) -> Path | None:
    """Write the summary's proposed law to ``path`` (JSON, atomically; an existing file refused
    without ``overwrite``): the law as data (terms, granularity, the constants found), the robot,
    the formula and its units, and where it was found. None (nothing written) when no law was
    proposed."""
    law = summary.get("proposed_law")
    if law is None:
        return None
    kept = {"format": KEPT_LAW_FORMAT, "robot": summary["robot"], "formula": law["formula"], "terms": law["terms"],
            "units": law["units"], "constants": law["constants"], "law": law["law"],
            "found_on": summary.get("source")}
    atomic_write(path, json.dumps(kept, indent=1), overwrite=overwrite)
    return Path(path)


def read_kept_law(path: Path, robot: str | None = None) -> dict:
    """A law kept by :func:`keep_law` (checked: its format, keys and terms; of ``robot`` when
    given).

    Raises:
        ValueError: the file cannot be read, is not a kept law, lacks a key, or is another robot's
            (the message names the file and the key).
    """
    from calib.effects.laws import law_from_dict

    d = read_json_file(Path(path), "kept law (JSON)", ValueError)
    if not isinstance(d, dict) or d.get("format") != KEPT_LAW_FORMAT:
        raise ValueError(f"{path}: key 'format' is not {KEPT_LAW_FORMAT!r}: not a law kept by pipeline.discover --law")
    for key in ("robot", "law"):
        if key not in d:
            raise ValueError(f"{path}: key {key!r} missing")
    try:
        law_from_dict(d["law"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: key 'law' is not a law's terms ({exc!r} missing or bad)") from None
    if robot is not None and d["robot"] != robot:
        raise ValueError(f"{path}: key 'robot' is {d['robot']!r}, a law of another robot than the {robot}")
    return d


def kept_law_effect(kept: dict, rec: Recording):
    """The kept law (:func:`read_kept_law`'s data) as a candidate effect on ``rec`` (name
    :data:`KEPT_LAW_NAME`; its terms and granularity kept, its constants refitted; a recorded
    channel it uses taken from ``rec.extras`` by time).

    Raises:
        ValueError: a law of another robot, or one using a channel ``rec`` does not record.
    """
    from calib.effects.laws import law_channels, law_effect, law_from_dict

    if kept["robot"] != rec.robot.name:
        raise ValueError(f"the kept law is of the {kept['robot']}, the recording of the {rec.robot.name}")
    terms, gran = law_from_dict(kept["law"])
    missing = [c for c in law_channels(terms) if c not in rec.extras]
    if missing:
        raise ValueError(f"the kept law uses the recorded channel {missing[0]!r}, which the recording lacks")
    channels = {c: rec.extras[c] for c in law_channels(terms)}
    return law_effect(terms, gran, channels, name=KEPT_LAW_NAME, channel_times_s=rec.t_s)
