"""The pages' transcripts run as written: every fenced block of README.md and docs/*.md whose lines
start with ``$ `` is run, command by command, in a temporary copy of ``examples/`` (as a new user
would from a fresh clone), and its output compared with the page, as doctests keep numpy's pages true.

The rules (docs/README.md, "Transcripts"): a line ``$ CMD`` is a command, the lines after it its
expected output (stdout and stderr together) until the next ``$ ``; ``[...]`` alone on a line
matches any run of lines (none included); a number matches when the output's rounds to it at the
digits printed (at most :data:`SIGNIFICANT_DIGITS`); a figure printed with a leading ``~`` (a
timing, or a figure another BLAS kernel prints otherwise, such as a singular matrix's condition
number) matches any number, the spaces before it any run of spaces; the rest of a line matches
exactly. A page's blocks run in order in one folder (a clone's root; ``$ cd DIR`` moves), with the
repository's python and ``HOME`` a temporary folder. A block not meant to run carries
``<!-- not run: why -->`` on the line before its fence, and is listed in :data:`NOT_RUN`.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from decimal import ROUND_HALF_EVEN, ROUND_HALF_UP, Decimal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PAGES = [REPO / "README.md"] + sorted((REPO / "docs").glob("*.md"))
#: The line that matches any run of output lines.
CUT = "[...]"
#: The comment, on the line before a fence, of a block not meant to run.
NOT_RUN_MARK = re.compile(r"<!--\s*not run:\s*(.+?)\s*-->")
#: The blocks each page marks as not run (their count): a new mark must be added here to skip.
NOT_RUN: dict[str, int] = {}
#: The most significant digits a figure is compared to: the pages print some figures to 17 (the
#: LinuxCNC files' parameters), whose last digits another BLAS kernel computes otherwise; the fits
#: behind them have condition numbers ~1e3 (the runs print them), so with eps 2.2e-16 they agree to
#: about 1e-13 relative, and 12 digits hold on any BLAS.
SIGNIFICANT_DIGITS = 12
#: A figure on the page or in the output; ``~`` before it on the page: any number.
NUMBER = re.compile(r"~?-?\d+(?:\.\d+)?(?:e[+-]?\d+)?")
#: What the pages' commands write in ``examples/`` (its .gitignore): left out of the copy, as from a clone.
EXAMPLE_OUTPUTS = [line.strip().rstrip("/").rpartition("/")[2]
                   for line in (REPO / "examples" / ".gitignore").read_text().splitlines()
                   if line.strip() and not line.startswith("#")]
#: The repository's top level a clone's folder links (what the pages' commands read, never write).
CLONE_LINKS = ("README.md", "pyproject.toml", "calib", "mjcf", "pipeline", "tests", "benchmarks", "docs")
#: A here-document in a command: its lines, to the word, are the command's, not its output.
HEREDOC = re.compile(r"<<-?\s*'?(\w+)'?")
#: A command may run this long (s) before the test fails.
COMMAND_TIMEOUT_S = 120


@dataclass
class Command:
    line: int  # the page's line of the ``$``
    text: str
    expected: list[str] = field(default_factory=list)


@dataclass
class Block:
    page: str
    line: int
    commands: list[Command]
    not_run: str | None  # why not, or None


def transcript_blocks(path: Path) -> list[Block]:
    """The fenced blocks of ``path`` whose first line is a ``$`` command, with their commands
    (a line ending in ``\\`` continues on the next) and expected output."""
    lines = path.read_text().splitlines()
    blocks, k = [], 0
    while k < len(lines):
        if not lines[k].startswith("```"):
            k += 1
            continue
        end = next(j for j in range(k + 1, len(lines)) if lines[j].startswith("```"))
        body = lines[k + 1:end]
        if body and body[0].startswith("$ "):
            mark = NOT_RUN_MARK.search(lines[k - 1]) if k else None
            blocks.append(Block(str(path.relative_to(REPO)), k + 1, parse_commands(body, k + 2),
                                mark.group(1) if mark else None))
        k = end + 1
    return blocks


def parse_commands(body: list[str], first_line: int) -> list[Command]:
    commands, k = [], 0
    while k < len(body):
        line = body[k]
        if line.startswith("$ "):
            text, start = line[2:], k
            while text.endswith("\\") and k + 1 < len(body):
                k += 1
                text = text[:-1] + " " + body[k].strip()
            here = HEREDOC.search(text)
            while here and k + 1 < len(body) and body[k].strip() != here.group(1):
                k += 1
                text += "\n" + body[k]
            commands.append(Command(first_line + start, text))
        else:
            commands[-1].expected.append(line)
        k += 1
    return commands


def number_matches(page: str, out: str) -> bool:
    """``out`` rounds to ``page`` at the digits ``page`` prints (either tie rule), at most
    :data:`SIGNIFICANT_DIGITS` of them; ``~`` any number."""
    if page.startswith("~") or page == out:
        return True
    page_mantissa, _, page_exp = page.partition("e")
    out_mantissa, _, out_exp = out.partition("e")
    if page_exp != out_exp or "." not in out_mantissa:
        return False
    printed = Decimal(page_mantissa)
    if len(printed.as_tuple().digits) > SIGNIFICANT_DIGITS:  # within one unit of the last digit held
        unit = Decimal(1).scaleb(printed.adjusted() - SIGNIFICANT_DIGITS + 1)
        return abs(Decimal(out_mantissa) - printed) < unit
    digits = Decimal(1).scaleb(printed.as_tuple().exponent)
    return any(Decimal(out_mantissa).quantize(digits, rounding=rule) == Decimal(page_mantissa)
               for rule in (ROUND_HALF_EVEN, ROUND_HALF_UP))


def text_matches(page: str, out: str, before_any_number: bool) -> bool:
    """The text between figures, exactly; before a ``~`` figure its spaces any run of spaces
    (the column's alignment, which the figure's width moves)."""
    if not before_any_number:
        return page == out
    return page.rstrip() == out.rstrip() and page[-1:].isspace() == out[-1:].isspace()


def line_matches(page: str, out: str) -> bool:
    page_numbers, out_numbers = NUMBER.findall(page), NUMBER.findall(out)
    page_text, out_text = NUMBER.split(page), NUMBER.split(out)
    if len(page_numbers) != len(out_numbers):
        return False
    any_number = [n.startswith("~") for n in page_numbers] + [False]
    return (all(text_matches(p, o, a) for p, o, a in zip(page_text, out_text, any_number))
            and all(number_matches(p, o) for p, o in zip(page_numbers, out_numbers)))


def lines_match(page: list[str], out: list[str]) -> bool:
    """``out`` matches ``page`` line by line, each :data:`CUT` standing for any run of lines."""
    matched = {0}  # how many output lines the page's lines so far can have matched
    for line in page:
        if line.strip() == CUT:
            matched = set(range(min(matched), len(out) + 1)) if matched else set()
        else:
            matched = {n + 1 for n in matched if n < len(out) and line_matches(line, out[n])}
    return len(out) in matched


def run_command(command: Command, cwd: Path, env: dict) -> tuple[Path, list[str]]:
    """Runs one command (``cd`` moves the folder) and returns the folder after it and its output."""
    if command.text.startswith("cd "):
        return cwd / command.text[3:].strip(), []
    text = re.sub(r"(^|(?<=\s))python(?=\s)", shlex.quote(sys.executable), command.text)
    done = subprocess.run(["bash", "-c", text], cwd=cwd, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=COMMAND_TIMEOUT_S)
    return cwd, done.stdout.replace(str(cwd) + os.sep, "").splitlines()


def page_env(home: Path) -> dict:
    return {**os.environ, "HOME": str(home), "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1",
            "MPLBACKEND": "Agg"}


def clone(root: Path) -> Path:
    """A fresh clone's folder: ``examples/`` copied (its inputs only), the rest of the repository's
    top level linked (the pages' ``PYTHONPATH=.`` and ``tests/`` work as in the repository)."""
    shutil.copytree(REPO / "examples", root / "examples", ignore=shutil.ignore_patterns(*EXAMPLE_OUTPUTS))
    for name in CLONE_LINKS:
        (root / name).symlink_to(REPO / name)
    return root


def run_page(page: str, tmp_path: Path) -> list[str]:
    """Runs a page's transcripts in order in a copy of ``examples/``; the mismatches, as text."""
    root = clone(tmp_path / "clone")
    (tmp_path / "home").mkdir()
    env, cwd, failures = page_env(tmp_path / "home"), root, []
    for block in transcript_blocks(REPO / page):
        if block.not_run:
            continue
        for command in block.commands:
            cwd, out = run_command(command, cwd, env)
            if not lines_match(command.expected, out):
                failures.append(f"{page}:{command.line}: $ {command.text}\n--- the page:\n"
                                + "\n".join(command.expected) + "\n--- the output:\n" + "\n".join(out))
    return failures


RUN_PAGES = [str(p.relative_to(REPO)) for p in PAGES
             if any(not b.not_run for b in transcript_blocks(p))]


@pytest.mark.slow
@pytest.mark.parametrize("page", RUN_PAGES)
def test_a_pages_transcripts_run_as_written(page, tmp_path):
    failures = run_page(page, tmp_path)
    assert not failures, "\n\n".join(failures)


def test_the_blocks_not_run_are_marked_and_listed():
    marked = {}
    for path in PAGES:
        for block in transcript_blocks(path):
            if block.not_run:
                marked[block.page] = marked.get(block.page, 0) + 1
    assert marked == NOT_RUN


def test_the_pages_with_transcripts_are_run():
    assert {"README.md", "docs/importer.md", "docs/commands.md", "docs/discovery.md", "docs/poor_pose_sets.md",
            "docs/compensation.md", "docs/real_data.md", "docs/klipper.md"} <= set(RUN_PAGES)


@pytest.mark.parametrize("page, out, expected", [
    ("position error, um mean  7.185", "position error, um mean  7.1853", True),
    ("position error, um mean  7.185", "position error, um mean  7.186", False),
    ("position error, um mean  7.185", "position error, um mean  7.18", False),
    ("dead_band = 0.005 +- 1.6e-08 mm", "dead_band = 0.005 +- 1.62e-08 mm", True),
    ("dead_band = 0.005 +- 1.6e-08 mm", "dead_band = 0.005 +- 1.6e-09 mm", False),
    ("wall time ~1.63 s", "wall time 2.20 s", True),
    ("um mean    53.984   ~18.478", "um mean    53.984    7.460", True),
    ("um mean    53.984   ~18.478", "um mean    53.984;   7.460", False),
    ("setp genhexkins.base.0.x 120.01937459946033", "setp genhexkins.base.0.x 120.01937459945594", True),
    ("setp genhexkins.base.0.x 120.01937459946033", "setp genhexkins.base.0.x 120.01937459846033", False),
    ("B6.z: +2.704 mm", "B5.z: +2.704 mm", False),
    ("wrote cnc/NOTES.md", "wrote cnc/NOTES.txt", False),
])
def test_a_line_matches_at_the_printed_digits(page, out, expected):
    assert line_matches(page, out) is expected


@pytest.mark.parametrize("page, out, expected", [
    (["a", CUT, "d"], ["a", "b", "c", "d"], True),
    (["a", CUT, "d"], ["a", "d"], True),
    (["a", "d"], ["a", "b", "d"], False),
    (["a", CUT], ["a"], True),
    ([CUT, "c"], ["a", "b"], False),
    (["a"], ["a", "b"], False),
])
def test_a_cut_matches_any_run_of_lines(page, out, expected):
    assert lines_match(page, out) is expected
