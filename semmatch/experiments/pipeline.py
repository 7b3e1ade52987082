"""Run the numbered notebooks through papermill with parameters from ``params.yaml``.

``params.yaml`` holds ``profile`` (the one ``dvc repro`` runs) and ``profiles``: for each
profile a ``common`` section given to every notebook plus one section per notebook (the key is
the notebook name without its number, e.g. ``simulate`` for ``01_simulate``). A notebook gets
``common`` merged with its own section as papermill parameters, plus ``profile``,
``data_root`` (default ``data/<profile>``) and ``figures_dir`` (default ``figures/<profile>``).

Command line (used by ``dvc.yaml``)::

    python -m semmatch.experiments run 01_simulate [--profile smoke]
    python -m semmatch.experiments all [--profile smoke] [--data-root DIR]
    python -m semmatch.experiments profiles
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import yaml

from ..io import atomic_write_text
from .protocol import check_protocol

__all__ = [
    "NOTEBOOKS",
    "ROOT",
    "ROOT_ENV",
    "TRAIN_ENV",
    "find_root",
    "NotebookFailed",
    "section_of",
    "read_params",
    "load_params",
    "METHOD_SETTING_KEYS",
    "run_method_settings",
    "notebook_parameters",
    "notebook_setup",
    "run_notebook",
    "run_all",
    "set_profile",
    "main",
]

#: environment variable naming the repository root (the folder with ``params.yaml``)
ROOT_ENV = "SEMMATCH_ROOT"


def find_root(start: str | os.PathLike | None = None) -> Path:
    """The repository root the pipeline reads ``params.yaml`` from and writes ``data/`` under.

    ``$SEMMATCH_ROOT`` when set, else the nearest folder at or above ``start`` (default: the
    working directory, e.g. ``notebooks/`` in Jupyter) that holds ``params.yaml``. Not the
    package's location: with a non-editable install, or one environment shared by two
    checkouts, that is not the checkout being worked in. Outside any checkout the source
    tree's root is the last resort (an editable install), then the working directory.

    Parameters
    ----------
    start : path, optional
        Where the search starts.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        If ``$SEMMATCH_ROOT`` is set to a folder without ``params.yaml``.
    """
    env = os.environ.get(ROOT_ENV)
    if env:
        root = Path(env).expanduser().resolve()
        if not (root / "params.yaml").is_file():
            raise FileNotFoundError(f"{ROOT_ENV}={env}: no params.yaml in {root} (it must name the repository root)")
        return root
    here = Path(start if start is not None else os.getcwd()).resolve()
    for folder in (here, *here.parents):
        if (folder / "params.yaml").is_file():
            return folder
    source = Path(__file__).resolve().parents[2]
    return source if (source / "params.yaml").is_file() else here


ROOT = find_root()

#: environment variable that makes every pipeline run train its networks (``make repro TRAIN=1``)
TRAIN_ENV = "SEMMATCH_TRAIN"

#: the notebooks in run order
NOTEBOOKS: tuple[str, ...] = (
    "01_simulate",
    "02_train_segmentation",
    "03_reconstruct_upper",
    "04_label_transfer",
    "05_evaluate_synthetic",
    "06_height_study",
    "07_real_data",
    "08_qualitative",
    "09_adapt_robot_view",
    "10_panoptic",
)


class NotebookFailed(RuntimeError):
    """A notebook raised; the message names the notebook, the cell and the parameters."""


def section_of(notebook: str) -> str:
    """The ``params.yaml`` section of a notebook: ``01_simulate`` -> ``simulate``."""
    if notebook not in NOTEBOOKS:
        raise ValueError(f"unknown notebook {notebook!r}; valid: {', '.join(NOTEBOOKS)}")
    return notebook.split("_", 1)[1]


#: profile keys (``common``) that carry a transfer method's parameters: key -> method. ``slic_2d``
#: is the analysis plan v2's speed lever (docs/analysis_plan_v2.md, "The 2d-slic lever")
METHOD_SETTING_KEYS: dict[str, str] = {"slic_2d": "2d-slic"}


def run_method_settings(params: Mapping) -> dict[str, dict]:
    """The transfer methods' settings a profile states, ``{method: {parameter: value}}``.

    Parameters
    ----------
    params : mapping
        A profile's ``common`` section or a notebook's parameters (e.g. ``{"slic_2d": slic_2d}``);
        keys of :data:`METHOD_SETTING_KEYS` that are absent or ``None`` leave their method at its
        defaults.

    Returns
    -------
    dict
        What every study passes on; each method checks its parameters where it runs
        (:func:`semmatch.transfer.settings_for`).

    Raises
    ------
    ValueError
        A setting that is not a mapping.
    """
    out = {}
    for key, method in METHOD_SETTING_KEYS.items():
        value = params.get(key)
        if value is not None and not isinstance(value, Mapping):
            raise ValueError(f"params.yaml {key}: expected a mapping of {method}'s parameters, got {value!r}")
        if value is not None:
            out[method] = dict(value)
    return out


#: parameters a researcher varies, settable at the top level of params.yaml (``null`` = the
#: active profile's value), so that ``dvc exp run -S eval_voxel_size=0.1`` works with a short key;
#: a key of ``common`` overrides it there, any other key the one notebook section that has it
OVERRIDABLE = ("eval_seeds", "methods", "networks", "fused_base", "voxel_size", "eval_voxel_size",
               "n_frames_upper", "n_frames_lower", "routes", "image_width", "image_height")
_TOP_LEVEL = ("profile", "profiles", *OVERRIDABLE)


def _apply_overrides(params_file: Path, data: dict, name: str, profile: dict) -> dict:
    """The profile with the non-null top-level overrides put where their key lives."""
    unknown = sorted(set(data) - set(_TOP_LEVEL))
    if unknown:
        raise ValueError(f"{params_file}: unknown top-level key(s) {', '.join(unknown)}; valid: "
                         f"{', '.join(_TOP_LEVEL)}")
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in profile.items()}
    for key in OVERRIDABLE:
        if data.get(key) is None:
            continue
        where = [sec for sec, v in out.items() if isinstance(v, dict) and key in v]
        if "common" in where:  # a common key; a notebook section's own key of that name stays
            where = ["common"]
        if len(where) != 1:
            raise ValueError(f"{params_file}: the override {key}={data[key]!r} must match exactly one "
                             f"section of profile {name!r}, found {where or 'none'}")
        out[where[0]][key] = data[key]
    return out


#: the file beside ``params.yaml`` that holds the profiles (kept out of params.yaml, which DVC shows whole)
PROFILES_FILE = "profiles.yaml"


def read_params(params_file: str | os.PathLike = ROOT / "params.yaml") -> dict:
    """The parameter file's top level, with ``profiles`` from :data:`PROFILES_FILE` beside it.

    A parameter file that holds its own ``profiles`` (a confirmatory run's, a test's) is used
    as it is.

    Raises
    ------
    FileNotFoundError
        If the parameter file is missing.
    ValueError
        If it (or the profiles file) is not a YAML mapping.
    """
    params_file = Path(params_file)
    try:
        data = yaml.safe_load(params_file.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{params_file}: no parameter file") from None
    if not isinstance(data, dict):
        raise ValueError(f"{params_file}: not a YAML mapping of parameters")
    beside = params_file.with_name(PROFILES_FILE)
    if "profiles" not in data and beside.is_file():
        profiles = yaml.safe_load(beside.read_text())
        if not isinstance(profiles, dict) or not isinstance(profiles.get("profiles"), dict):
            raise ValueError(f"{beside}: expected a top-level 'profiles:' mapping")
        data = {**data, "profiles": profiles["profiles"]}
    return data


def load_params(params_file: str | os.PathLike = ROOT / "params.yaml", profile: str | None = None) -> dict:
    """Load ``params.yaml`` (:func:`read_params`) and return the selected profile as a dict (plus ``profile``).

    Top-level keys of :data:`OVERRIDABLE` that are not ``null`` replace the profile's value
    (in ``common`` or in the section that holds the key).

    Raises
    ------
    ValueError
        If the profile does not exist (the message lists the valid ones), a top-level key is
        unknown, or an override matches no section of the profile.
    """
    params_file = Path(params_file)
    data = read_params(params_file)
    profiles = data.get("profiles") or {}
    name = profile or data.get("profile")
    if name not in profiles:
        raise ValueError(
            f"{params_file}: profile {name!r} does not exist; valid profiles: {', '.join(sorted(profiles))}"
        )
    out = _apply_overrides(params_file, data, name, profiles[name])
    out["profile"] = name
    return out


def notebook_parameters(
    notebook: str, profile: str | None = None, params_file: str | os.PathLike = ROOT / "params.yaml",
    **overrides,
) -> dict:
    """Papermill parameters of ``notebook``: the profile's ``common`` + its own section."""
    p = load_params(params_file, profile)
    params = dict(p.get("common") or {})
    params.update(p.get(section_of(notebook)) or {})
    params["profile"] = p["profile"]
    params.setdefault("data_root", f"data/{p['profile']}")
    params.setdefault("figures_dir", f"figures/{p['profile']}")
    params.setdefault("shipped_models", f"models/{p['profile']}")  # notebook 02: the shipped networks
    params.update({k: v for k, v in overrides.items() if v is not None})
    return params


def _quiet_dash_comm() -> None:
    """Give Dash a comm that talks to no frontend.

    Open3D imports Dash, which opens a ``dash`` comm when imported in a Jupyter kernel; only
    Dash's own JupyterLab extension (disabled by scripts/setup.sh) would handle it, so nbconvert
    and papermill warn "No handler found for comm target 'dash'". Other comms are untouched.
    """
    try:
        import comm
    except ImportError:  # pragma: no cover  (not in a Jupyter environment)
        return
    if getattr(comm.create_comm, "_semmatch_quiet", False):
        return
    create = comm.create_comm

    def create_comm(*args, **kwargs):
        if kwargs.get("target_name") == "dash":
            return comm.DummyComm(*args, **kwargs)
        return create(*args, **kwargs)

    create_comm._semmatch_quiet = True
    comm.create_comm = create_comm


def notebook_setup(notebook: str, namespace: dict) -> dict:
    """Make a notebook run the same in plain Jupyter as under papermill.

    Called by every notebook right after its parameters cell: the working directory becomes the
    repository root (the notebook's relative paths, e.g. ``data/<profile>``, resolve there
    whatever folder Jupyter started in; under :func:`run_notebook`, which sets
    ``SEMMATCH_PIPELINE``, papermill's ``cwd`` is kept), and every parameter the notebook left at ``None``
    takes the active profile's value: the profile named by ``profile`` (when set), else by the
    ``SEMMATCH_PROFILE`` environment variable, else ``params.yaml``'s ``profile`` (the parameter
    file is ``SEMMATCH_PARAMS`` when set: :func:`run_notebook` passes its own). Under
    papermill the injected parameters are not ``None`` and stay as they are.

    Parameters
    ----------
    notebook : str
        The notebook's name (one of :data:`NOTEBOOKS`).
    namespace : dict
        The notebook's globals.

    Returns
    -------
    dict
        The filled-in parameters (``globals().update(...)`` them).
    """
    if not os.environ.get("SEMMATCH_PIPELINE"):  # under run_notebook papermill sets the directory
        os.chdir(ROOT)
    _quiet_dash_comm()
    from .stagedeps import record_loaded_modules

    record_loaded_modules(notebook)  # only with SEMMATCH_RECORD_MODULES set (the DVC deps test)
    profile = namespace.get("profile") or os.environ.get("SEMMATCH_PROFILE") or None
    params_file = os.environ.get("SEMMATCH_PARAMS") or ROOT / "params.yaml"  # run_notebook's file
    params = notebook_parameters(notebook, profile, params_file)
    return {k: v for k, v in params.items() if k in namespace and namespace[k] is None}


def _declared(src: Path, params: dict, own: dict) -> dict:
    """Keep the parameters the notebook declares; a key of its own section it does not declare
    is an error (a typo in params.yaml must not pass silently), common keys are optional."""
    import papermill as pm

    declared = set(pm.inspect_notebook(str(src)))
    unknown = sorted(set(own) - declared)
    if unknown:
        raise ValueError(f"{src}: params.yaml gives {', '.join(unknown)}, which the notebook's parameters "
                         f"cell does not declare (declared: {', '.join(sorted(declared))})")
    return {k: v for k, v in params.items() if k in declared}


def run_notebook(
    notebook: str,
    profile: str | None = None,
    *,
    params_file: str | os.PathLike = ROOT / "params.yaml",
    notebooks_dir: str | os.PathLike = ROOT / "notebooks",
    reports_dir: str | os.PathLike | None = None,
    cwd: str | os.PathLike = ROOT,
    progress: bool = False,
    log_output: bool = False,
    scheduler: str | None = None,
    **overrides,
) -> Path:
    """Execute one notebook with papermill; return the executed copy.

    The executed copy goes to ``reports/<profile>/<notebook>.ipynb`` (or ``reports_dir``).
    With ``log_output`` the cells' output (progress lines, tables) is also streamed to this
    process's log while the notebook runs (papermill's ``--log-output``), so a long stage run by
    ``dvc repro`` shows its progress on the console. ``scheduler`` (else the profile's
    ``common.scheduler``) is the address of a Dask scheduler the notebook's per-scene tasks run
    on (:mod:`semmatch.runtime.engine`; passed to the kernel as ``SEMMATCH_SCHEDULER``).

    Raises
    ------
    NotebookFailed
        Naming the notebook, the failing cell (index and first line), the error and the
        parameters it ran with.
    """
    import papermill as pm

    params = notebook_parameters(notebook, profile, params_file, **overrides)
    from ..runtime.engine import SCHEDULER_ENV, check_scheduler, resolve_scheduler

    # --scheduler, else the profile's common.scheduler, else SEMMATCH_SCHEDULER: reached first,
    # before anything is written (an unreachable address is a clear error within seconds)
    address = resolve_scheduler(scheduler or (load_params(params_file, params["profile"]).get("common") or {})
                                .get("scheduler"))
    if address:
        check_scheduler(address)
    check_protocol(load_params(params_file, params["profile"]).get("common") or {},
                   where=f"{params_file} (profile {params['profile']})")
    src = Path(notebooks_dir) / f"{notebook}.ipynb"
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such notebook")
    params = _declared(src, params, load_params(params_file, params["profile"]).get(section_of(notebook)) or {})
    out_dir = Path(reports_dir) if reports_dir is not None else Path(cwd) / "reports" / params["profile"]
    out_dir.mkdir(parents=True, exist_ok=True)
    out = out_dir / f"{notebook}.ipynb"
    t0 = time.perf_counter()
    # the kernel inherits the environment: plain-text progress lines instead of widgets that an
    # executed notebook would keep frozen at 0 % (semmatch.runtime.progress); papermill sets the working
    # directory itself (notebook_setup leaves it)
    kernel_env = {"SEMMATCH_PROGRESS": "text", "SEMMATCH_PIPELINE": "1",
                  "SEMMATCH_PARAMS": str(Path(params_file).resolve())}
    if address:
        kernel_env[SCHEDULER_ENV] = address
    saved = {k: os.environ.get(k) for k in kernel_env}
    os.environ.update(kernel_env)
    try:
        pm.execute_notebook(
            str(src), str(out), parameters=params, cwd=str(cwd), progress_bar=progress,
            kernel_name="python3", log_output=log_output,
        )
    except pm.PapermillExecutionError as e:
        first = (e.source or "").strip().splitlines()[:1]
        raise NotebookFailed(
            f"notebook {notebook} failed in cell {e.cell_index} (execution count {e.exec_count}"
            f"{', ' + repr(first[0]) if first else ''}): {e.ename}: {e.evalue}\n"
            f"  parameters: {params}\n  executed copy with the traceback: {out}"
        ) from None
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    from .headline import write_stage_metrics

    figures_dir = Path(params.get("figures_dir") or f"figures/{params['profile']}")
    write_stage_metrics(figures_dir if figures_dir.is_absolute() else Path(cwd) / figures_dir, section_of(notebook))
    print(f"[semmatch] {notebook} ({params['profile']}) done in {time.perf_counter() - t0:.0f} s -> {out}",
          file=sys.stderr)
    return out


def run_all(profile: str | None = None, *, until: str | None = None, **kwargs) -> list[Path]:
    """Run every notebook in order (``until``: stop after this one)."""
    outs = []
    for nb in NOTEBOOKS:
        outs.append(run_notebook(nb, profile, **kwargs))
        if nb == until:
            break
    return outs


def set_profile(profile: str, params_file: str | os.PathLike = ROOT / "params.yaml") -> None:
    """Make ``profile`` the one ``dvc repro`` runs (rewrites the ``profile:`` line, keeps comments)."""
    params_file = Path(params_file)
    load_params(params_file, profile)  # refuses unknown profiles with the valid ones
    lines = params_file.read_text().splitlines(keepends=True)
    for i, line in enumerate(lines):
        if line.startswith("profile:"):
            lines[i] = f"profile: {profile}\n"
            break
    else:
        raise ValueError(f"{params_file}: no top-level 'profile:' line")
    atomic_write_text(params_file, "".join(lines))


def _parser(extra_commands: Sequence[Callable] = ()) -> argparse.ArgumentParser:
    """The argument parser of :func:`main`."""
    ap = argparse.ArgumentParser(prog="python -m semmatch.experiments", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run one notebook")
    r.add_argument("notebook", choices=NOTEBOOKS)
    a = sub.add_parser("all", help="run every notebook in order")
    a.add_argument("--until", choices=NOTEBOOKS)
    for p in (r, a):
        p.add_argument("--profile", help="profile of params.yaml (default: its 'profile')")
        p.add_argument("--params", default=str(ROOT / "params.yaml"))
        p.add_argument("--data-root", help="override common.data_root")
        p.add_argument("--figures-dir", help="override common.figures_dir")
        p.add_argument("--reports-dir", help="where executed notebooks go (default reports/<profile>)")
        p.add_argument("--quiet", action="store_true",
                       help="do not stream the cells' output (progress lines, tables) to the console")
        p.add_argument("--train", action="store_true", default=os.environ.get(TRAIN_ENV) == "1",
                       help=f"train every network instead of using the shipped ones (default: on when ${TRAIN_ENV}=1, "
                            f"as `make repro TRAIN=1` sets it)")
        p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786) to run the per-scene tasks on "
                                           "(default: the profile's common.scheduler, else local processes)")
    sub.add_parser("profiles", help="list the profiles of params.yaml")
    for add in extra_commands:  # subcommands defined elsewhere (confirm, ship: __main__)
        add(sub)
    sp = sub.add_parser("set-profile", help="select the profile dvc repro runs")
    sp.add_argument("name")
    rd = sub.add_parser("readme", help="write README.md's results section from figures/<profile>/")
    rd.add_argument("--profile", help="profile whose figures to show (default: params.yaml's)")
    rd.add_argument("--confirm", metavar="NAME", help="headline from figures/confirm/NAME (default: the analysis "
                    "plan's confirmatory run when it exists; --confirm none: the profile's figures)")
    sn = sub.add_parser("snapshot", help="small copies of the executed notebooks for git (reports/snapshot/<profile>/)")
    sn.add_argument("--profile", help="profile whose executed notebooks to copy (default: params.yaml's)")
    sn.add_argument("--max-width", type=int, default=960, help="scale figures down to this width (pixels)")
    return ap


def _readme(args: argparse.Namespace) -> int:
    """``readme``: README.md's results section from the profile's (or a confirmatory run's) figures."""
    from .readme import confirmatory_run, update_readme

    name = load_params(ROOT / "params.yaml", args.profile)["profile"]
    if args.confirm is None:
        confirm = confirmatory_run(ROOT / "figures")
    elif args.confirm == "none":
        confirm = None
    else:
        confirm = ROOT / "figures" / "confirm" / args.confirm
        if not (confirm / "confirm.json").is_file():
            raise FileNotFoundError(f"{confirm}: no confirm.json (run make confirm SEEDS=... NAME={args.confirm})")
    update_readme(ROOT / "README.md", ROOT / "figures" / name, confirmatory_dir=confirm)
    return 0


def _snapshot(args: argparse.Namespace) -> int:
    """``snapshot``: small copies of the profile's executed notebooks."""
    from .snapshot import snapshot_reports

    name = load_params(ROOT / "params.yaml", args.profile)["profile"]
    for p in snapshot_reports(ROOT / "reports" / name, ROOT / "reports" / "snapshot" / name, profile=name,
                              max_width=args.max_width, root=ROOT):
        print(f"{p.relative_to(ROOT)}: {p.stat().st_size / 1024:.0f} KB")
    return 0


def _run_notebooks(args: argparse.Namespace) -> int:
    """``run`` and ``all``: one notebook, or every one in order."""
    kw = dict(params_file=args.params, reports_dir=args.reports_dir, data_root=args.data_root,
              figures_dir=args.figures_dir, log_output=not args.quiet, scheduler=args.scheduler)
    if args.train:  # notebook 02 trains every network, notebook 09 fine-tunes the adapted ones (the notebooks with
        # a `retrain` parameter)
        kw["retrain"] = True
    if not args.quiet:
        import logging

        # papermill logs the streamed cell output at INFO on its own logger
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        log = logging.getLogger("papermill")
        log.addHandler(handler)
        log.setLevel(logging.INFO)
    if args.cmd == "run":
        run_notebook(args.notebook, args.profile, **kw)
    else:
        run_all(args.profile, until=args.until, **kw)
    return 0


def main(argv: list[str] | None = None, extra_commands: Sequence[Callable] = ()) -> int:
    """``python -m semmatch.experiments``.

    ``extra_commands``: functions that each add a subcommand to the subparsers, setting a
    ``handler(args) -> int`` default (the runner's ``__main__`` adds ``confirm`` and ``ship``,
    kept out of this module so that editing them reruns no pipeline stage).
    """
    args = _parser(extra_commands).parse_args(argv)
    try:
        if args.cmd == "profiles":
            print("\n".join(sorted(read_params().get("profiles", {}))))
            return 0
        if getattr(args, "handler", None) is not None:  # an extra command
            return args.handler(args)
        if args.cmd == "set-profile":
            set_profile(args.name)
            return 0
        if args.cmd == "readme":
            return _readme(args)
        if args.cmd == "snapshot":
            return _snapshot(args)
        return _run_notebooks(args)
    except (NotebookFailed, ValueError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
