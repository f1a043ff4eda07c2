"""Does a change keep behaviour? Run a fixed set of commands and keep what they print and write.

``python benchmarks/same_behaviour.py record DIR`` runs every command of :data:`COMMANDS` (runs
and discoveries of every robot, a real file, a re-reference, a fleet, the exports) from this
tree, each in ``DIR/<name>/``, keeping its standard output, its exit status and every file it
wrote; ``python benchmarks/same_behaviour.py compare A B`` says, command by command, what
differs between two such records (a refactor's branch against main: nothing should).

What is not behaviour is masked before the comparison: wall times (``... s`` figures and the
``timing`` / ``*_s`` keys of JSON files), the record's own folder in paths, and the Rerun
``.rrd`` files (their recording ids and clocks differ on every run; their content is the
summary's and the report's, compared here). Numbers are compared to the bit as written.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

# (name, arguments of python -m ...); {out} is the command's own folder, {prev} the record.
COMMANDS: tuple[tuple[str, str], ...] = (
    ("run_hexapod", "pipeline.run --out {out} --summary-json {out}/s.json --report {out}/r.html --quiet"),
    ("run_delta", "pipeline.run --robot delta --out {out} --summary-json {out}/s.json --report {out}/r.html"),
    ("run_rus", "pipeline.run --robot rus --out {out} --summary-json {out}/s.json --report {out}/r.html"),
    ("run_linear_delta", "pipeline.run --robot linear_delta --out {out} --summary-json {out}/s.json "
                         "--report {out}/r.html"),
    ("run_forward_noprior", "pipeline.run --robot delta --method forward --no-prior --poses 30 --seed 2 "
                            "--out {out} --summary-json {out}/s.json"),
    ("run_friction", "pipeline.run --poses 60 --heldout 20 --friction 1.0 --seed 3 --name machine --out {out} "
                     "--summary-json {out}/s.json"),
    ("real_capture", "pipeline.run --real {prev}/convert_capture/capture.csv --out {out} "
                     "--summary-json {out}/s.json --report {out}/r.html"),
    ("real_table4", "pipeline.run --real examples/table4.csv --out {out} --summary-json {out}/s.json "
                    "--report {out}/r.html"),
    ("real_delta_tracker", "pipeline.run --real {prev}/convert_delta/delta_tracker.csv --out {out} "
                           "--summary-json {out}/s.json"),
    ("real_two_days", "pipeline.run --real {prev}/convert_days/days.csv --out {out} --summary-json {out}/s.json"),
    ("discover_two_days", "pipeline.discover --real {prev}/convert_days/days.csv --out {out} "
                          "--summary-json {out}/s.json --no-resim"),
    ("discover_hexapod", "pipeline.discover --scenario joint_friction --out {out} --summary-json {out}/s.json "
                         "--report {out}/r.html --no-resim"),
    ("discover_delta", "pipeline.discover --robot delta --scenario compliance --out {out} "
                       "--summary-json {out}/s.json --no-resim"),
    ("discover_rus", "pipeline.discover --robot rus --scenario joint_friction --out {out} "
                     "--summary-json {out}/s.json --no-resim"),
    ("discover_linear_delta", "pipeline.discover --robot linear_delta --scenario actuator_scale --out {out} "
                              "--summary-json {out}/s.json --no-resim"),
    ("discover_resim", "pipeline.discover --scenario compliance --out {out} --summary-json {out}/s.json"),
    ("discover_real", "pipeline.discover --real {prev}/convert_capture/capture.csv --out {out} "
                      "--summary-json {out}/s.json --report {out}/r.html --no-resim"),
    ("fleet", "pipeline.fleet {prev}/fleet_in --out {out} --workers 1 --quiet"),
    ("export_report", "pipeline.export --calibration {prev}/run_hexapod/hexapod_paper.calibration.json "
                      "--to report --out {out}/report"),
    ("export_linuxcnc", "pipeline.export --calibration {prev}/run_hexapod/hexapod_paper.calibration.json "
                        "--to linuxcnc --out {out}/linuxcnc"),
    ("klipper_convert", "pipeline.convert examples/klipper/printer.cfg --klipper --out {out}/printer"),
    ("klipper_probe", "pipeline.probe {prev}/klipper_convert/printer.probe.json --out {out}"),
    ("klipper_export", "pipeline.export --calibration {prev}/klipper_probe/printer.calibration.json --to klipper "
                       "--out {out}/export"),
)

# what must exist before a command: (command, how to make it)
PREPARE = {
    "real_capture": ("convert_capture", "pipeline.convert examples/capture.csv --map examples/stewart.toml "
                                        "--out {out}/capture"),
    "real_delta_tracker": ("convert_delta", "pipeline.convert examples/delta_tracker/delta_tracker.csv "
                                            "--map examples/delta_tracker/delta.toml --out {out}/delta_tracker"),
    "real_two_days": ("convert_days", "pipeline.convert examples/two_days/grid.csv examples/two_days/feb12.csv "
                                      "--map examples/two_days/map.toml --out {out}/days"),
}

TIME = re.compile(r"\d+(\.\d+)?(e[-+]?\d+)? ?(s|ms)\b")


def run(name: str, args: str, record: Path) -> None:
    out = record / name
    out.mkdir(parents=True, exist_ok=True)
    line = args.format(out=out, prev=record)
    proc = subprocess.run([sys.executable, "-m", *line.split()], cwd=REPO, capture_output=True, text=True,
                          env={**os.environ, "PYTHONHASHSEED": "0"})
    (out / "_stdout.txt").write_text(proc.stdout)
    (out / "_stderr.txt").write_text(proc.stderr)
    (out / "_rc.txt").write_text(f"{proc.returncode}\n")
    print(f"{name}: exit {proc.returncode}", flush=True)


def record(folder: Path, only=()) -> None:
    folder = folder.resolve()
    for name, args in PREPARE.values():
        if not (folder / name).exists():
            run(name, args, folder)
    fleet = folder / "fleet_in"
    fleet.mkdir(parents=True, exist_ok=True)
    for src in (REPO / "examples/table4", folder / "convert_delta/delta_tracker", folder / "convert_capture/capture"):
        for ext in (".csv", ".json"):
            (fleet / (src.name + ext)).write_bytes(src.with_suffix(ext).read_bytes())
    wanted = set(only)
    for name, args in COMMANDS:
        if not wanted or name in wanted:
            run(name, args, folder)


def is_time(key: str) -> bool:
    return key in ("timing", "seconds") or key.endswith(("_s", "_seconds"))


def masked_json(value):
    if isinstance(value, dict):
        return {k: ("<time>" if is_time(k) else masked_json(v)) for k, v in value.items()}
    if isinstance(value, list):
        return [masked_json(v) for v in value]
    return value


def masked(path: Path, root: Path) -> str:
    text = path.read_text(errors="replace").replace(str(root), "<record>")
    if path.suffix == ".json":
        try:
            return json.dumps(masked_json(json.loads(text)), indent=1, sort_keys=True)
        except json.JSONDecodeError:
            pass
    if path.name in ("fleet.csv", "fleet.md"):  # the wall time column, next to last
        sep = "," if path.suffix == ".csv" else "|"
        text = "\n".join(sep.join(c if i != len(line.split(sep)) - 2 - (sep == "|") else "<time>"
                                   for i, c in enumerate(line.split(sep))) for line in text.splitlines())
    return TIME.sub("<time>", text)


def compare(a: Path, b: Path) -> int:
    a, b = a.resolve(), b.resolve()
    differing = 0
    for name, _ in (*COMMANDS, *PREPARE.values()):
        da, db = a / name, b / name
        if not da.exists() or not db.exists():
            print(f"{name}: missing in {'A' if not da.exists() else 'B'}")
            continue
        fa = {p.relative_to(da) for p in da.rglob("*") if p.is_file() and p.suffix != ".rrd"}
        fb = {p.relative_to(db) for p in db.rglob("*") if p.is_file() and p.suffix != ".rrd"}
        bad = [f"only in A: {f}" for f in sorted(fa - fb)] + [f"only in B: {f}" for f in sorted(fb - fa)]
        for f in sorted(fa & fb):
            if f.name == "_stderr.txt":
                continue
            if masked(da / f, a) != masked(db / f, b):
                bad.append(f"differs: {f}")
        differing += bool(bad)
        print(f"{name}: {'same' if not bad else '; '.join(bad)}")
    print(f"{differing} of {len(COMMANDS) + len(PREPARE)} commands differ")
    return 1 if differing else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    r = sub.add_parser("record")
    r.add_argument("folder", type=Path)
    r.add_argument("only", nargs="*", help="command names (default: all)")
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = parser.parse_args()
    if args.what == "record":
        record(args.folder, args.only)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
