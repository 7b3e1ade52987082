"""The package's layout and import graph: a top level of at most twelve packages or public
modules, no import circles between its parts or its modules, the old import paths gone and named
nowhere, and the sizes (no function over 80 lines of code, no module over 600 lines without a
stated reason at its top).

The graph is read statically (``ast``) from every module of ``semmatch``, counting imports
anywhere in a module (also those inside functions, which run only when called), but not those
for type annotations only (``if TYPE_CHECKING:``), which never run. A *unit* is a
top-level part: a subpackage (``semmatch.transfer``) or a loose module directly under
``semmatch``. The flat module paths of earlier versions (:data:`REMOVED`) were deprecation shims
for one release and are gone; the loose modules of the third layout (:data:`MOVED`) moved into
packages without shims.
"""

from __future__ import annotations

import ast
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "semmatch"
#: at most this many entries directly under semmatch/ (__init__.py and __main__.py aside)
MAX_TOP_LEVEL = 12
#: what may sit directly under semmatch/ besides the packages and modules (Python's byte-code cache)
TOP_LEVEL_IGNORED = ("__init__.py", "__main__.py", "__pycache__")
#: old flat module paths (deprecated for one release, then removed) -> where the module lives now
REMOVED = {
    "semmatch.dbscan": "semmatch.transfer.dbscan", "semmatch.metrics": "semmatch.evaluate.metrics",
    "semmatch.odometry": "semmatch.poses.odometry", "semmatch.planes": "semmatch.transfer.planes",
    "semmatch.pose_graph": "semmatch.poses.pose_graph", "semmatch.recordings": "semmatch.io.recordings",
    "semmatch.reference": "semmatch.evaluate.reference", "semmatch.registration": "semmatch.poses.registration",
    "semmatch.rgbd_odometry": "semmatch.poses.rgbd_odometry", "semmatch.stats": "semmatch.evaluate.stats",
    "semmatch.trajectory_metrics": "semmatch.poses.trajectory_metrics",
}
#: loose top-level modules (and one package) of the second layout -> their package now (moved, no shims)
MOVED = {
    "semmatch.engine": "semmatch.runtime.engine", "semmatch.workers": "semmatch.runtime.workers",
    "semmatch.threads": "semmatch.runtime.threads", "semmatch.progress": "semmatch.runtime.progress",
    "semmatch.geometry": "semmatch.io.geometry", "semmatch.labels": "semmatch.io.labels",
    "semmatch.panoptic": "semmatch.transfer.panoptic", "semmatch.viz": "semmatch.plots.views",
    "semmatch.adapt": "semmatch.segment.adapt",
}
OLD_PATHS = {**REMOVED, **MOVED}


def _modules() -> dict[str, tuple[Path, bool]]:
    """Module name -> (source file, is a package) for every module of semmatch."""
    out = {}
    for f in sorted(PACKAGE.rglob("*.py")):
        parts = list(f.relative_to(ROOT).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (f, is_pkg)
    return out


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The semmatch module ``name`` is, or is inside of (``semmatch.io.read_map`` -> ``semmatch.io``)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _runtime_nodes(tree: ast.AST):
    """The nodes of ``tree`` outside ``if TYPE_CHECKING:`` blocks (imports for annotations only,
    which never run)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if not (isinstance(child, ast.If) and isinstance(child.test, ast.Name) and child.test.id == "TYPE_CHECKING"):
                todo.append(child)


def _imports(tree: ast.AST, package: str) -> set[str]:
    """The semmatch modules an AST imports (``from m import x``: ``m.x`` when ``x`` is a module)."""
    out = set()
    for node in _runtime_nodes(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = parts[: len(parts) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            names = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod for a in node.names]
        else:
            continue
        out |= {r for n in names if n.startswith("semmatch") and (r := _resolve(n))}
    return out


def _graph() -> dict[str, set[str]]:
    """Module -> the modules it imports, without the imports of a module's own parent packages
    (Python runs those first anyway)."""
    g = {}
    for m, (f, is_pkg) in MODULES.items():
        package = m if is_pkg else m.rpartition(".")[0]
        deps = _imports(ast.parse(f.read_text(), filename=str(f)), package)
        g[m] = {d for d in deps if d != m and not m.startswith(d + ".")}
    return g


def _circles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected components of more than one node (Tarjan, iterative)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in graph:
                    continue
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = set()
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.add(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(frozenset(comp))
    return out


def _unit(module: str) -> str:
    return ".".join(module.split(".")[:2])


def test_old_flat_paths_are_gone_and_their_modules_live_on():
    for old, new in OLD_PATHS.items():
        assert old not in MODULES, f"{old} is back: it moved to {new} (no shims at old paths)"
        assert new in MODULES, f"{new} (the home of the old {old}) is not a module of ours"


def top_level_problems(package: Path, limit: int = MAX_TOP_LEVEL) -> list[str]:
    """What is wrong with the top level of ``package``: more than ``limit`` entries (its
    ``__init__.py``, ``__main__.py`` and byte-code cache aside), or an entry that is neither a
    package (a folder with an ``__init__.py``) nor a public module (a ``.py`` file declaring
    ``__all__``, the names a user imports from it)."""
    entries = sorted(p for p in package.iterdir() if p.name not in TOP_LEVEL_IGNORED)
    out = []
    if len(entries) > limit:
        out.append(f"{len(entries)} entries at the top of {package.name}/ (at most {limit}): "
                   + " ".join(p.name + ("/" if p.is_dir() else "") for p in entries))
    for p in entries:
        if p.is_dir() and not (p / "__init__.py").is_file():
            out.append(f"{p.name}/: a folder that is no package (no __init__.py)")
        elif p.is_file() and p.suffix != ".py":
            out.append(f"{p.name}: not a Python module (data belongs inside the package that reads it)")
        elif p.is_file() and not any(isinstance(n, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)
                for n in ast.parse(p.read_text(), filename=str(p)).body):
            out.append(f"{p.name}: a loose module without __all__ (a top-level module is one a user imports)")
    return out


def test_the_top_level_is_at_most_twelve_packages_or_public_modules():
    problems = top_level_problems(PACKAGE)
    assert not problems, "the top of semmatch/ (the pipeline's packages and its runtime only):\n" + "\n".join(problems)


def test_the_top_level_check_finds_a_crowded_or_untidy_top(tmp_path):
    """The 22 entries of the second layout are refused; so are a data file, a folder that is no
    package and a module without a public surface."""
    top = tmp_path / "semmatch"
    top.mkdir()
    for name in ("__init__", "__main__", "engine", "geometry", "labels", "panoptic", "progress", "threads",
                 "viz", "workers"):
        (top / f"{name}.py").write_text("__all__ = []\n")
    for name in ("adapt", "cli", "evaluate", "experiments", "fusion", "io", "online", "plots", "poses", "segment",
                 "sim", "transfer"):
        (top / name).mkdir()
        (top / name / "__init__.py").write_text("")
    (top / "__pycache__").mkdir()
    problems = top_level_problems(top)
    assert len(problems) == 1 and problems[0].startswith("20 entries at the top of semmatch/ (at most 12)")
    shutil.rmtree(top / "adapt")  # the third layout: twelve packages (adapt/ inside segment/, ...)
    for name in ("engine", "geometry", "labels", "panoptic", "progress", "threads", "viz", "workers"):
        (top / f"{name}.py").unlink()
    (top / "runtime").mkdir()
    (top / "runtime" / "__init__.py").write_text("")
    assert top_level_problems(top) == []
    for name in ("online", "poses", "sim"):  # room for three untidy entries
        shutil.rmtree(top / name)
    (top / "plan.yaml").write_text("")
    (top / "notes").mkdir()
    (top / "helpers.py").write_text("def f():\n    pass\n")
    assert sorted(p.split(":")[0] for p in top_level_problems(top)) == ["helpers.py", "notes/", "plan.yaml"]


def test_no_circles_between_the_packages_parts():
    """No unit imports from a unit that imports it (no back arrows), also inside functions."""
    g = _graph()
    units: dict[str, set[str]] = {}
    for m, deps in g.items():
        if m == "semmatch":
            continue
        units.setdefault(_unit(m), set()).update(_unit(d) for d in deps if _unit(d) not in (_unit(m), "semmatch"))
    circles = _circles(units)
    assert not circles, f"import circles between parts of semmatch: {circles}"


def test_no_circles_between_modules():
    """No module imports from a module that imports it, also inside one part and inside functions."""
    circles = _circles(_graph())
    assert not circles, f"import circles between modules: {circles}"


def test_the_circle_finder_finds_circles():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [frozenset("abc")]
    assert _circles({"a": {"b"}, "b": set()}) == []


def _code_files():
    """(name, source) of every Python source of ours: package, tests, scripts, notebook cells."""
    this = Path(__file__).resolve()
    for folder in ("semmatch", "tests", "scripts"):
        for f in sorted((ROOT / folder).rglob("*.py")):
            if f.resolve() != this:
                yield f.relative_to(ROOT).as_posix(), f.read_text()
    for f in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(f.read_text())["cells"]
        yield f.relative_to(ROOT).as_posix(), "\n".join(
            "".join(c["source"]) if isinstance(c["source"], list) else c["source"] for c in cells)


def test_nothing_of_ours_uses_an_old_import_path():
    """Package, tests, scripts and notebooks name the current paths only (imports, patch targets,
    docstrings): an old flat path would fail to import."""
    old = re.compile(r"\b(" + "|".join(re.escape(s) for s in sorted(OLD_PATHS)) + r")\b(?!\.py)")
    found = [f"{name}: {m.group(1)}" for name, text in _code_files() for m in old.finditer(text)]
    assert not found, "old import paths in use:\n" + "\n".join(found)


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=ROOT)


@pytest.mark.slow
def test_every_module_imports():
    """Every module of semmatch imports (optional third-party packages aside)."""
    names = sorted(m for m in MODULES if not m.endswith("__main__"))
    code = (
        "import importlib\n"
        f"for name in {names!r}:\n"
        "    try:\n"
        "        importlib.import_module(name)\n"
        "    except ModuleNotFoundError as e:\n"
        "        if (e.name or 'semmatch').startswith('semmatch'):\n"
        "            raise\n"  # an optional third-party package (habitat_sim, detectron2) is fine
    )
    run = _run(code)
    assert run.returncode == 0, run.stderr[-3000:]


# ----------------------------------------------------------------------------- sizes

#: a module longer than this says why at its top: its docstring holds a paragraph beginning "Size:"
MAX_MODULE_LINES = 600
#: a function's code lines: its body without the docstring, blank lines and comment-only lines
MAX_FUNCTION_LINES = 80
def _code_lines(path: Path) -> tuple[ast.Module, set[int]]:
    """The module's AST and the numbers of its lines that hold code (not only a comment, not blank)."""
    import io
    import tokenize

    text = path.read_text()
    lines: set[int] = set()
    skip = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT, tokenize.ENDMARKER}
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type not in skip:
            lines.update(range(tok.start[0], tok.end[0] + 1))
    return ast.parse(text, filename=str(path)), lines


def function_sizes(path: Path) -> dict[str, int]:
    """``{qualified name: code lines}`` of every function (and method) in a source file: the lines
    of its body, docstring, blank and comment-only lines left out (nested functions count in the
    function around them too)."""
    tree, code = _code_lines(path)
    out = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                body = child.body
                doc = (body[0].lineno, body[0].end_lineno) if (
                    isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)) else (0, -1)
                span = range(body[0].lineno, child.end_lineno + 1)
                out[prefix + child.name] = sum(1 for n in span if n in code and not doc[0] <= n <= doc[1])
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def test_no_function_over_80_lines_of_code():
    long = [f"{m}.{q}: {n} lines" for m, (f, _) in MODULES.items() for q, n in function_sizes(f).items()
            if n > MAX_FUNCTION_LINES]
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines of code (split them):\n" + "\n".join(long)


def test_a_module_over_600_lines_says_why_at_its_top():
    unsaid = []
    for m, (f, _) in MODULES.items():
        n = len(f.read_text().splitlines())
        doc = ast.get_docstring(ast.parse(f.read_text())) or ""
        if n > MAX_MODULE_LINES and "Size:" not in doc:
            unsaid.append(f"{m}: {n} lines")
    assert not unsaid, (f"modules over {MAX_MODULE_LINES} lines without a 'Size:' paragraph in their docstring "
                        "(split them, or say why not):\n" + "\n".join(unsaid))


def test_the_size_counts(tmp_path):
    f = tmp_path / "m.py"
    f.write_text('def f(x):\n    """Doc\n\n    more."""\n\n    # a comment\n    y = (x +\n         1)  # tail\n'
                 '    s = """a\n\n    b"""\n    return y\n\n\nclass C:\n    def g(self):\n        def h():\n'
                 '            return 1\n        return h\n')
    assert function_sizes(f) == {"f": 6, "C.g": 3, "C.g.h": 1}
