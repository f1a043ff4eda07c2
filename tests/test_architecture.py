"""The project's import structure (docs/architecture.md): no circle anywhere, and the rooms of
``pipeline/`` import one way, from the commands down to ``mjcf`` and ``calib``.

Imports are read from the source (every ``import`` statement, at module level or inside a
function), so a deferred import counts as an arrow too."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("calib", "mjcf", "pipeline")

#: Each layer, top first: a module may import its own layer's modules and those of lower layers.
#: ``pipeline.<command>`` (the top-level modules) and ``pipeline.cli`` are the commands.
LAYERS = (
    ("commands",),
    ("pipeline.workflows",),
    ("pipeline.deliveries",),
    ("pipeline.views", "pipeline.simulation", "pipeline.report"),
    ("pipeline.formats", "pipeline.execution"),
    ("mjcf",),
    ("calib",),
)


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def project_modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}


def imported_modules(name: str, path: Path, known: set[str]) -> set[str]:
    """The project modules ``name`` imports (the module itself or, for ``from X import y``, X.y
    when that is a module, else X)."""
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in known:  # a name inside a module: the module
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def import_graph() -> dict[str, set[str]]:
    mods = project_modules()
    known = set(mods)
    return {n: imported_modules(n, p, known) for n, p in mods.items()}


def layer_of(module: str) -> int:
    if module.startswith("pipeline.") and module.count(".") == 1 and \
            not any(module == room for layer in LAYERS for room in layer):
        return 0  # a command (pipeline.run, ...) or pipeline.cli
    if module == "pipeline":
        return 0
    for i, rooms in enumerate(LAYERS):
        if any(module == r or module.startswith(r + ".") for r in rooms):
            return i
    raise AssertionError(f"{module} is in no layer of docs/architecture.md")


def test_no_import_circle_anywhere():
    graph = import_graph()
    state, stack, circles = {}, [], []

    def visit(n):
        state[n] = "open"
        stack.append(n)
        for m in sorted(graph[n]):
            if state.get(m) == "open":
                circles.append(stack[stack.index(m):] + [m])
            elif m not in state:
                visit(m)
        stack.pop()
        state[n] = "done"

    for n in sorted(graph):
        if n not in state:
            visit(n)
    assert not circles, "import circles: " + "; ".join(" -> ".join(c) for c in circles)


def test_rooms_import_downwards_only():
    graph = import_graph()
    upward = [f"{a} -> {b}" for a, targets in graph.items() for b in targets
              if a.split(".")[0] in PACKAGES and layer_of(b) < layer_of(a)]
    assert not upward, "imports against the layers: " + ", ".join(sorted(upward))


def test_the_checks_see_a_planted_upward_import_and_circle(tmp_path):
    """The graph is read correctly: the known arrows are there (a check that could not fail
    would pass on an empty graph)."""
    graph = import_graph()
    assert "pipeline.workflows.calibration" in graph["pipeline.run"]
    assert "pipeline.formats.outputs" in graph["pipeline.formats.recording"]
    assert "mjcf.simulator" in graph["pipeline.simulation.testbed"]
    assert "calib.engine" in graph["pipeline.workflows.calibration"]
    assert layer_of("pipeline.views.charts") < layer_of("pipeline.formats.outputs")


@pytest.mark.parametrize("package", ["pipeline.formats", "pipeline.views", "pipeline.simulation",
                                     "pipeline.execution", "pipeline.workflows", "pipeline.deliveries",
                                     "pipeline.report"])
def test_every_room_exports_what_it_names(package):
    import importlib

    mod = importlib.import_module(package)
    for name in mod.__all__:
        assert getattr(mod, name) is not None, f"{package}.{name}"


def imported_by_name(path: Path) -> set[str]:
    """What a module hands ``import_module`` / ``__import__`` (imports made at call time, which no
    ``import`` statement shows): a module's name, from a string or a module-level constant;
    ``"relative"`` for a name inside its own package (an f-string starting with ``.`` or
    ``__package__``); ``"unread"`` for anything else."""
    tree = ast.parse(path.read_text())
    constants = {t.id: node.value.value for node in tree.body if isinstance(node, ast.Assign)
                 and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)
                 for t in node.targets if isinstance(t, ast.Name)}

    def named(arg) -> str:
        if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
            return arg.value
        if isinstance(arg, ast.Name) and arg.id in constants:
            return constants[arg.id]
        if isinstance(arg, ast.JoinedStr) and arg.values:
            first = arg.values[0]
            if isinstance(first, ast.Constant) and str(first.value).startswith("."):
                return "relative"
            if isinstance(first, ast.FormattedValue) and isinstance(first.value, ast.Name) \
                    and first.value.id in ("__package__", "__name__"):
                return "relative"
        return "unread"

    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call) and node.args
             and ((isinstance(node.func, ast.Name) and node.func.id in ("import_module", "__import__"))
                  or (isinstance(node.func, ast.Attribute) and node.func.attr == "import_module"))]
    return {named(call.args[0]) for call in calls}


#: The one arrow against the layers, made by name at call time: ``Calibration.deliver`` looks up
#: the deliveries' one registry (calib.calibration.DELIVERY_PACKAGE; docs/architecture.md).
NAMED_UPWARD = {("calib.calibration", "pipeline.deliveries")}


def test_the_only_import_by_name_against_the_layers_is_the_registry_of_deliveries():
    """An import made by name at call time counts as an arrow too: every one in the project is
    read (none left unread), and the only one against the layers is calib.calibration's lookup
    of the registry of deliveries (made when a delivery is asked for, calib loaded by then)."""
    by_name = {(a, b) for a, p in project_modules().items() for b in imported_by_name(p) if b != "relative"}
    assert not {a for a, b in by_name if b == "unread"}, "imports by name the check cannot read"
    upward = {(a, b) for a, b in by_name if layer_of(b) < layer_of(a)}
    assert upward == NAMED_UPWARD
    from calib.calibration import DELIVERY_PACKAGE

    assert ("calib.calibration", DELIVERY_PACKAGE) in by_name  # the check sees the arrow it allows


@pytest.mark.slow
def test_the_words_of_a_verdict_load_no_rerun():
    """The discovery's and the fleet's workflows word their verdicts without Rerun (a fleet's Dask
    workers load none): Rerun is imported only where a .rrd file is written."""
    import subprocess
    import sys

    code = ("import sys, pipeline.workflows.discovery, pipeline.workflows.fleet, pipeline.report.text; "
            "print('rerun' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "False"


def test_the_report_and_its_words_import_no_rerun_and_no_numpy():
    """The report's model and its wording (the terminal summary, the Rerun markdown, the HTML's
    phrases) are pure text: no statement of either module, deferred ones included, imports Rerun
    or NumPy (the views log the markdown; the fleet's workers word a verdict without a viewer)."""
    def third_party(path: Path) -> set[str]:
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names.add((node.module or "").split(".")[0])
        return names

    for module in ("model", "text", "verdict_words"):
        imported = third_party(ROOT / "pipeline" / "report" / f"{module}.py")
        assert not imported & {"rerun", "numpy"}, (module, sorted(imported))
    assert "rerun" in third_party(ROOT / "pipeline" / "views" / "run_view.py")  # the check sees an import


def command_lines_worded(source: str) -> list[int]:
    """Lines of ``source`` whose string literals (f-strings' text included), docstrings left out,
    name a command line (``python -m``): words a person reads, composed where they are run."""
    tree = ast.parse(source)
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return [node.lineno for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings
            and "python -m" in node.value]


def test_calib_words_no_command_line():
    """calib returns causes and typed evidence; the words, command-line advice included, are
    pipeline's (the verdict's: :mod:`pipeline.report.verdict_words`). Docstrings and comments may
    name the commands that use a function."""
    found = {str(path.relative_to(ROOT)): lines for path in (ROOT / "calib").rglob("*.py")
             if (lines := command_lines_worded(path.read_text()))}
    assert not found, found


def test_the_check_sees_a_command_line_in_words_not_in_a_docstring():
    planted = '''"""run python -m pipeline.run"""
def f(where):
    """python -m pipeline.discover"""
    # python -m pipeline.discover
    return f"run python -m pipeline.discover --real {where}"
'''
    assert command_lines_worded(planted) == [5]


def runnable_modules() -> list[str]:
    """The project's modules with an ``if __name__ == "__main__"`` block (``python -m`` runs them)."""
    def is_main_block(node) -> bool:
        return (isinstance(node, ast.If) and isinstance(node.test, ast.Compare)
                and isinstance(node.test.left, ast.Name) and node.test.left.id == "__name__"
                and any(isinstance(c, ast.Constant) and c.value == "__main__" for c in node.test.comparators))

    return sorted(name for name, path in project_modules().items()
                  if any(is_main_block(node) for node in ast.parse(path.read_text()).body))


def test_the_runnable_modules_are_found():
    found = runnable_modules()
    assert "mjcf.hexapod" in found and "pipeline.run" in found and "calib.engine" not in found


@pytest.mark.slow
@pytest.mark.parametrize("module", runnable_modules())
def test_a_runnable_module_has_a_command_line_whose_help_writes_nothing(module, tmp_path):
    """Every module ``python -m`` runs has a command line: ``--help`` prints its usage, exits 0
    and writes nothing, neither where it runs nor in the repository (before: ``python -m
    mjcf.hexapod --help`` ignored --help and rewrote the tracked mjcf/hexapod_paper_actual.xml)."""
    import os
    import subprocess
    import sys

    def files():
        return {p: p.stat().st_mtime_ns for pkg in PACKAGES for p in (ROOT / pkg).rglob("*") if p.is_file()
                and "__pycache__" not in p.parts}

    before = files()
    env = dict(os.environ, PYTHONPATH=str(ROOT), HOME=str(tmp_path))
    done = subprocess.run([sys.executable, "-m", module, "--help"], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.startswith(f"usage: python -m {module}"), done.stderr
    assert list(tmp_path.iterdir()) == [] and files() == before


def test_no_module_imports_another_modules_private_name():
    """No ``from X import _name`` in calib, mjcf or pipeline (a name shared by two modules is a
    public one, in its module's ``__all__``); the check sees a planted one."""
    def private_imports(source: str) -> list[str]:
        return [f"{node.module}.{a.name}" for node in ast.walk(ast.parse(source))
                if isinstance(node, ast.ImportFrom) and node.module != "__future__"
                for a in node.names if a.name.startswith("_")]

    assert private_imports("from .joint_fit import _design, EffectFit") == ["joint_fit._design"]
    found = {name: private_imports(path.read_text()) for name, path in project_modules().items()}
    assert not {k: v for k, v in found.items() if v}


#: The rooms of the effects' discovery (docs/architecture.md), and their limits (issue 47): a
#: module of about 600 lines at most, no function over 80.
DISCOVERY_ROOMS = ("whitening", "search", "joint_fit", "selection", "remainder", "located", "gross_rows", "evidence",
                   "discovery")
ROOM_LINES, FUNCTION_LINES = 600, 80


@pytest.mark.parametrize("room", DISCOVERY_ROOMS)
def test_a_room_of_the_discovery_is_small_and_its_functions_short(room):
    path = ROOT / "calib" / "effects" / f"{room}.py"
    source = path.read_text()
    lengths = [(node.name, node.end_lineno - node.lineno + 1) for node in ast.walk(ast.parse(source))
               if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]
    long = [(name, n) for name, n in lengths if n > FUNCTION_LINES]
    assert source.count("\n") <= ROOM_LINES and not long, (source.count("\n"), long)


#: The longest function the team keeps, docstring included (lines).
MAX_FUNCTION_LINES = 80


def test_no_function_is_longer_than_the_team_keeps():
    """A function over :data:`MAX_FUNCTION_LINES` lines (docstring included) in calib, mjcf or
    pipeline is named with its length: split it along its own steps."""
    long = []
    for name, path in sorted(project_modules().items()):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{name}.{node.name}: {lines} lines")
    assert not long, long
