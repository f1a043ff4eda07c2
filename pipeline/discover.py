"""``python -m pipeline.discover --real FILE``: find the physics the geometric model left out.

A thin front end of :func:`pipeline.workflows.discovery.run_discovery` (which says what it does):
parse the flags, call it, print its report (:func:`pipeline.report.text.terminal_lines`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from calib.effects import EFFECTS
from calib.robots import ROBOTS
from pipeline.cli import ArgumentParser, cli_main, nonnegative_int
from pipeline.report.text import terminal_lines
from pipeline.workflows.discovery import DiscoveryReport, DiscoverySettings, run_discovery

__all__ = ["build_parser", "settings_from_args", "run", "main"]


def _names(text: str) -> tuple[str, ...]:
    """``"a,b"`` -> ``("a", "b")``, each a registered effect."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    for n in names:
        if n not in EFFECTS:
            raise argparse.ArgumentTypeError(f"unknown effect {n!r}: expected one of {', '.join(EFFECTS)}")
    return names


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="python -m pipeline.discover",
        description="Find the physics a robot's geometric model leaves out: calibrate the geometry, locate "
                    f"the mismatch, name the effect ({', '.join(EFFECTS)}; those that apply to the robot), fit it, "
                    "and show the held-out fit improve.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--real", type=Path, help="recording to analyse (.csv with its .json sidecar)")
    src.add_argument("--scenario", type=_names, metavar="EFFECT[,EFFECT...]",
                     help="analyse a seeded simulated recording of --robot carrying these effects (pipeline.simulation; "
                          f"comma-separated, from {', '.join(EFFECTS)})")
    p.add_argument("--robot", choices=tuple(ROBOTS), default=None,
                   help="the robot of --scenario (default hexapod); with --real, the robot the file must be of "
                        "(default: the one its sidecar names)")
    p.add_argument("--scenario-seed", type=nonnegative_int, default=0, help="seed of the --scenario recording")
    p.add_argument("--scenario-granularity", choices=("shared", "per_chain"), default="shared",
                   help="the --scenario's effects: one value for every joint, or each joint its own (0.3 to 1.0 "
                        "times the largest)")
    p.add_argument("--candidates", type=_names, default=None, metavar="EFFECT[,EFFECT...]",
                   help="narrow the library to these effects (comma-separated; default every effect that applies to "
                        "the robot)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the held-out split and cross-validation folds")
    p.add_argument("--no-resim", action="store_true", help="skip the MuJoCo re-simulation")
    p.add_argument("--no-sysid", action="store_true", help="re-simulate without the mujoco.sysid re-fit")
    p.add_argument("--out", type=Path, default=Path("recordings"), help="folder of the .rrd")
    p.add_argument("--name", default=None, help="base name of the .rrd (default <recording>_discover)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing output files")
    p.add_argument("--summary-json", type=Path, default=None, help="write the summary as JSON")
    p.add_argument("--report", type=Path, default=None, metavar="PATH.html",
                   help="write the report a lab keeps: one self-contained HTML file (verdict, effects with their "
                        "evidence, a proposed law, parameters with +-2 sigma and their tolerance verdicts, held-out "
                        "errors plotted, the compensation table)")
    p.add_argument("--law", type=Path, default=None, metavar="FILE",
                   help="keep the proposed law (if one is proposed) in this JSON file, for --use-law on the next recording")
    p.add_argument("--use-law", type=Path, default=None, metavar="FILE",
                   help="a law kept by --law: one more candidate effect (kept_law), its constants refitted")
    p.add_argument("--export-mjcf", type=Path, default=None, metavar="PATH",
                   help="also write the identified machine, with the effects MuJoCo can hold, as a MuJoCo model "
                        "(MJCF .xml) to this path (docs/export_mjcf.md)")
    return p


def settings_from_args(args: argparse.Namespace) -> DiscoverySettings:
    """The :class:`DiscoverySettings` of parsed flags."""
    return DiscoverySettings(real=args.real, scenario=args.scenario, robot=args.robot,
                             scenario_seed=args.scenario_seed, scenario_granularity=args.scenario_granularity,
                             candidates=args.candidates, seed=args.seed,
                             resim=not args.no_resim, sysid=not args.no_sysid, out=args.out, name=args.name,
                             overwrite=args.overwrite, summary_json=args.summary_json, law_out=args.law,
                             use_law=args.use_law, export_mjcf=args.export_mjcf, report=args.report)


def run(argv: list[str] | None = None) -> DiscoveryReport:
    """Parse ``argv``, run the discovery, print the report; raises on bad input (see :func:`main`)."""
    report = run_discovery(settings_from_args(build_parser().parse_args(argv)))
    for line in terminal_lines(report.report):
        print(line)
    return report


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.discover``: exit 2 and one line on a bad input or output."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
