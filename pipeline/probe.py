"""``python -m pipeline.probe NAME.probe.json --out DIR``: a Delta printer (linear, or rotary: the
``delta`` robot of a ``rotary_delta`` config) calibrated from probe touches, manual heights and
distances (a probe-data file written by ``python -m pipeline.convert printer.cfg --klipper``): ``DIR/NAME.calibration.json`` (for ``python -m pipeline.export``) and the
observability statement ``DIR/NAME.observability.txt``, printed too (docs/klipper.md).

A dedicated command rather than ``pipeline.run --real``: a run fits poses at joints and judges
them on held-out poses; probe data are heights and distances. Bad input: exit 2, one line.
"""

from __future__ import annotations

import argparse

from pipeline.cli import ArgumentParser, cli_main
from pipeline.workflows.klipper import ProbeRunResult, fit_probe_file

__all__ = ["build_parser", "run", "main"]


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m pipeline.probe",
                       description="Calibrate a Delta printer (linear or rotary) from a probe-data file (touches, manual heights, "
                                   "distances): the MAP fit with the robot's tolerances as the prior.")
    p.add_argument("probe", help="the probe-data file NAME.probe.json (python -m pipeline.convert --klipper)")
    p.add_argument("--out", required=True, help="folder for NAME.calibration.json and NAME.observability.txt")
    p.add_argument("--name", help="NAME of the outputs (default: the probe file's)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing outputs")
    return p


def run(argv: list[str] | None = None) -> ProbeRunResult:
    """Parse ``argv``, fit, print what was written and the statement."""
    args = build_parser().parse_args(argv)
    result = fit_probe_file(args.probe, args.out, name=args.name, overwrite=args.overwrite)
    rms = ", ".join(f"{k} {1e3 * v:.1f} um" for k, v in result.fit.residual_rms_mm.items())
    print(f"wrote {result.calibration_path} and {result.statement_path}: residual RMS {rms}, "
          f"{result.fit.iterations} iterations")
    print(result.fit.statement())
    return result


def main(argv: list[str] | None = None) -> int:
    """Run; a refused input or output ends with one line on stderr and exit status 2."""
    return cli_main(run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
