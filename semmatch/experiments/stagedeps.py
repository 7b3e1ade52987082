"""The code each pipeline stage runs: the semmatch modules a notebook can import.

DVC reruns a stage when one of its dependencies changes, so a stage must depend on every module
it runs and, to be useful, on no other. :func:`stage_modules` finds them statically: the
``import`` statements of the notebook's code cells and of the stage command's module
(``python -m semmatch.experiments``: :mod:`semmatch.experiments.__main__`), followed transitively through the package, counting
imports anywhere in a module (also those inside functions, which run only when called), the
parent packages of every module, and the lazily exported names of a package (an ``_EXPORTS``
table of ``name -> submodule``, as :mod:`semmatch.segment` has).

Modules that no stage computes with are left out (``leave_out``, default :data:`LEAVE_OUT`),
and imports are not followed into them: the presentation-only :data:`DISPLAY_ONLY` (the
interactive 3D views of :mod:`semmatch.plots.views` appear only in the executed report; the README's
results section and the report snapshots are written from finished tables by their own
commands) and :data:`OTHER_COMMANDS` (the stage command's other subcommands, ``confirm`` and
``ship``, which only register their arguments when a stage runs). Editing them reruns no
stage. The pipeline's generator (``scripts/dvc_stages.py``) also leaves out
:mod:`semmatch.plots` for a stage that draws no figure file.

:func:`record_loaded_modules` is the runtime check: under the pipeline with
``SEMMATCH_RECORD_MODULES=<folder>`` set, every notebook writes the semmatch modules it
actually loaded to ``<folder>/<notebook>.txt`` when its kernel exits; the smoke test compares
them with ``dvc.yaml``.
"""

from __future__ import annotations

import ast
import atexit
import json
import os
import sys
from pathlib import Path

__all__ = ["stage_modules", "record_loaded_modules", "RECORD_ENV", "DISPLAY_ONLY", "OTHER_COMMANDS", "LEAVE_OUT",
           "RUNNER"]

#: environment variable naming the folder where notebooks record the modules they loaded
RECORD_ENV = "SEMMATCH_RECORD_MODULES"

_ROOT = Path(__file__).resolve().parents[2]
_PACKAGE = "semmatch"

#: presentation-only modules (with their submodules): what they draw or write is only shown or
#: read by people, never by a stage (3D views in the reports; the README's results section and
#: the report snapshots, written from finished tables by their own commands)
DISPLAY_ONLY = ("semmatch.plots.views", "semmatch.experiments.readme", "semmatch.experiments.snapshot")
#: the stage command's other subcommands (confirmatory runs, shipping networks, re-judging a run)
OTHER_COMMANDS = ("semmatch.experiments.confirm", "semmatch.experiments.rejudge")
#: what no stage depends on, nor on what only these import
LEAVE_OUT = DISPLAY_ONLY + OTHER_COMMANDS
#: the module the stage command runs (``python -m semmatch.experiments run NN_name``)
RUNNER = "semmatch.experiments.__main__"


def _under(name: str, packages: tuple[str, ...]) -> bool:
    """True when module ``name`` is one of ``packages`` or inside one of them."""
    return any(name == p or name.startswith(p + ".") for p in packages)


def _module_file(name: str, root: Path) -> Path | None:
    """The source file of module ``name`` under ``root`` (a package's ``__init__.py``), or None."""
    p = root.joinpath(*name.split("."))
    if (p / "__init__.py").is_file():
        return p / "__init__.py"
    if p.with_suffix(".py").is_file():
        return p.with_suffix(".py")
    return None


def _imported_names(tree: ast.AST, package: str) -> set[str]:
    """Every ``semmatch`` module name an AST may import (``from m import x`` also gives ``m.x``,
    which counts where ``x`` is a submodule)."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = parts[: len(parts) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return {m for m in out if m == _PACKAGE or m.startswith(_PACKAGE + ".")}


def _lazy_exports(tree: ast.AST, package: str) -> set[str]:
    """Submodules named by a package's ``_EXPORTS = {name: submodule}`` table."""
    for node in getattr(tree, "body", []):
        if (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "_EXPORTS" for t in node.targets)
                and isinstance(node.value, ast.Dict)):
            return {f"{package}.{v.value}" for v in node.value.values
                    if isinstance(v, ast.Constant) and isinstance(v.value, str)}
    return set()


def _closure(names: set[str], root: Path, leave_out: tuple[str, ...] = ()) -> dict[str, Path]:
    """Modules reachable from ``names`` (with their parent packages) -> source file, not entering
    the modules of ``leave_out``."""
    seen: dict[str, Path] = {}
    todo = sorted(names)
    while todo:
        parts = todo.pop().split(".")
        for i in range(1, len(parts) + 1):
            mod = ".".join(parts[:i])
            if _under(mod, leave_out):
                break
            f = _module_file(mod, root)
            if f is None or mod in seen:
                continue
            seen[mod] = f
            package = mod if f.name == "__init__.py" else mod.rpartition(".")[0]
            tree = ast.parse(f.read_text(), filename=str(f))
            todo += sorted(_imported_names(tree, package))
            if f.name == "__init__.py":
                todo += sorted(_lazy_exports(tree, mod))
    return seen


def _notebook_code(path: Path) -> str:
    """The code cells of a notebook as one Python source (IPython magics and shell lines dropped)."""
    cells = json.loads(path.read_text())["cells"]
    lines = []
    for c in cells:
        if c.get("cell_type") == "code":
            src = c["source"] if isinstance(c["source"], str) else "".join(c["source"])
            lines += [ln for ln in src.splitlines() if not ln.lstrip().startswith(("%", "!"))]
    return "\n".join(lines)


def stage_modules(notebook: str | os.PathLike, *, root: str | os.PathLike = _ROOT,
                  runner: str = RUNNER, leave_out: tuple[str, ...] = LEAVE_OUT) -> list[str]:
    """Source files of every semmatch module a pipeline stage can run.

    Parameters
    ----------
    notebook : str or path
        The stage's notebook (a path, or a name under ``<root>/notebooks``).
    root : path
        Repository root (the folder holding the ``semmatch`` package).
    runner : str
        Module of the stage command, included with its imports.
    leave_out : tuple of str
        Modules (and their submodules) the stage must not depend on; imports are not followed
        into them.

    Returns
    -------
    list of str
        Paths relative to ``root`` (POSIX), sorted.

    Raises
    ------
    FileNotFoundError
        If the notebook does not exist.
    SyntaxError
        If a module or a code cell of the notebook is not valid Python (named in the error).
    """
    root = Path(root)
    nb = Path(notebook)
    if not nb.suffix:
        nb = root / "notebooks" / f"{nb}.ipynb"
    if not nb.is_file():
        raise FileNotFoundError(f"{nb}: no such notebook")
    try:
        names = _imported_names(ast.parse(_notebook_code(nb), filename=str(nb)), "")
    except SyntaxError as e:
        raise SyntaxError(f"{nb}: a code cell is not valid Python: {e}") from None
    files = _closure(names | {runner}, root, tuple(leave_out))
    return sorted(f.relative_to(root).as_posix() for f in files.values())


def record_loaded_modules(notebook: str, folder: str | os.PathLike | None = None) -> Path | None:
    """Write the semmatch modules loaded by this process to ``<folder>/<notebook>.txt`` at exit.

    Parameters
    ----------
    notebook : str
        The notebook's name (the file name of the record).
    folder : path, optional
        Default: the folder named by ``SEMMATCH_RECORD_MODULES``; nothing is recorded when
        neither is given.

    Notes
    -----
    The modules of :data:`LEAVE_OUT` are not recorded: stages leave them out by design.

    Returns
    -------
    Path or None
        The record that will be written, or None when recording is off.
    """
    folder = folder if folder is not None else os.environ.get(RECORD_ENV)
    if not folder:
        return None
    out = Path(folder) / f"{notebook}.txt"

    def _write() -> None:
        files = set()
        for m in list(sys.modules.values()):
            f = getattr(m, "__file__", None)
            name = getattr(m, "__name__", "")
            if f and _under(name, (_PACKAGE,)) and not _under(name, LEAVE_OUT):
                p = Path(f).resolve()
                files.add(p.relative_to(_ROOT).as_posix() if p.is_relative_to(_ROOT) else str(p))
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(".tmp")
        tmp.write_text("\n".join(sorted(files)) + "\n")
        os.replace(tmp, out)

    atexit.register(_write)
    return out
