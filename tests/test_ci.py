"""CI runs what the README tells a new user to run (.ci/run): the install-and-test command verbatim,
on every core (pytest-xdist), then the tests again, on every core, on another BLAS kernel."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def readme_test_command() -> str:
    """The README's install-and-test line (the indented command under "Install and run the tests")."""
    text = (ROOT / "README.md").read_text()
    found = re.search(r"Install and run the tests:\n\n    (.+)\n", text)
    assert found, "README: no install-and-test command"
    return found.group(1)


def test_the_readmes_test_command_runs_the_suite_on_every_core():
    command = readme_test_command()
    pytest_part = command.split("&&")[-1].split()
    assert pytest_part[:3] == ["python", "-m", "pytest"] and "-n" in pytest_part
    assert pytest_part[pytest_part.index("-n") + 1] == "auto", command
    assert "pytest-xdist" in (ROOT / "pyproject.toml").read_text()


def test_ci_runs_the_readmes_command_then_again_on_every_core_with_the_prescott_kernel():
    script = (ROOT / ".ci" / "run").read_text()
    command = readme_test_command()
    runs = [line for line in script.splitlines() if "python -m pytest" in line and not line.lstrip().startswith(("#", "echo"))]
    assert len(runs) == 2, runs
    assert runs[0].startswith(command), runs[0]
    pytest_part = command.split("&&")[-1].strip()
    assert runs[1].startswith(f"OPENBLAS_NUM_THREADS=1 OPENBLAS_CORETYPE=Prescott {pytest_part}"), runs[1]
