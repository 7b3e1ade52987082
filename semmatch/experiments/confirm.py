"""Confirmatory runs: every evaluation study of a profile on fresh scenes, with the shipped networks.

``make confirm SEEDS="9111 9112 9113" [NAME=mine]`` runs
``python -m semmatch.experiments confirm --seeds ... --name ...``: the base profile (``full``)
with its evaluation seeds replaced by the given ones (each seed gives one scene of every kind),
the networks and flip choice shipped in ``models/<profile>/`` (nothing is trained), and every
other choice as the profile makes it on its validation scenes (the odometry gate of notebook 07,
the panoptic clustering radius of notebook 10). It writes

* ``data/confirm/<name>/`` the data (and ``params.yaml``, the parameters it ran with),
* ``figures/confirm/<name>/`` the tables, per-scene CSVs, claims tables, figures, the analysis
  plan's verdict per claim (``verdicts.csv`` / ``.md``,
  :func:`semmatch.experiments.claims.judge_figures`) and ``confirm.json`` (seeds, networks'
  SHA-256, code version, wall time per stage),
* ``reports/confirm/<name>/`` the executed notebooks.

Stage 09 (robot-view adaptation) scores the adapted networks shipped in
``models/<profile>/adapted/`` (it is skipped where none are shipped: a confirmatory run trains
nothing) and judges the adaptation claims of ``adapt_plan.yaml`` on its tables
(:func:`semmatch.experiments.adapt_claims.judge_adaptation`, ``adapt_verdicts.md``).
``--notebooks`` runs some notebooks in an existing run (e.g. stage 09 once adapted networks are
shipped), ``--in-home`` adds the in-home adaptation study. Seeds used for training, validation or development are refused
(:func:`semmatch.experiments.protocol.check_confirm_seeds`). ``ship`` writes a shipped folder
from trained checkpoints (:func:`semmatch.segment.shipping.ship_networks`).
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import yaml

from ..io import atomic_write_text
from .analysis_plan import PLAN_FILE, PLAN_V2_FILE, AnalysisPlan, plan_for_seeds
from .pipeline import NOTEBOOKS, ROOT, notebook_parameters, read_params, run_method_settings, run_notebook
from .protocol import check_confirm_seeds, check_protocol

__all__ = ["SKIPPED", "confirm_name", "write_confirm_params", "unshipped_networks", "run_confirm",
           "code_version", "add_confirm_parser", "add_ship_parser", "add_ship_adapted_parser", "ADAPT_NOTEBOOK",
           "adapted_networks_source"]

#: notebooks a confirmatory run leaves out, and why (printed when skipped)
SKIPPED: dict[str, str] = {
    "09_adapt_robot_view": "skipped: it would fine-tune networks, and models/<profile>/adapted/ holds no shipped "
                           "adaptation (a confirmatory run trains nothing)",
}
#: the notebook that scores the shipped adapted networks (run only when they are shipped)
ADAPT_NOTEBOOK = "09_adapt_robot_view"


def adapted_networks_source(shipped_dir: str | os.PathLike) -> str | None:
    """Where a confirmatory run's adapted networks come from: ``"shipped"`` (``shipped_dir/adapted``
    holds a shipped adaptation; notebook 09 then uses it or fails, never fine-tuning) or None
    (none shipped: notebook 09 is skipped, also with ``allow_training``: the smoke-sized networks
    a test trains in a few steps are too weak to label the robot's frames for adaptation)."""
    from .shipped_adaptation import MANIFEST

    return "shipped" if (Path(shipped_dir) / "adapted" / MANIFEST).is_file() else None


def confirm_name(seeds: Sequence[int]) -> str:
    """The default run name of a seed list: ``seeds-9111-9112`` (``seeds-9111-9134-n24`` for many)."""
    seeds = [int(s) for s in seeds]
    if len(seeds) <= 6:
        return "seeds-" + "-".join(map(str, seeds))
    return f"seeds-{min(seeds)}-{max(seeds)}-n{len(seeds)}"


def code_version(root: str | os.PathLike = ROOT) -> str | None:
    """``git describe --always --dirty`` of the checkout (None outside git)."""
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty", "--abbrev=40"], cwd=root,
                             capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def write_confirm_params(seeds: Sequence[int], out: str | os.PathLike, *, base_profile: str = "full",
                         params_file: str | os.PathLike = ROOT / "params.yaml",
                         shipped_dir: str | os.PathLike | None = None) -> Path:
    """Write the parameter file of a confirmatory run: the base profile with ``eval_seeds = seeds``.

    The base profile is taken as written in ``params_file`` (its top-level overrides, meant for
    quick experiments, do not apply). Its ``networks`` are those of the plan that judges ``seeds``
    (:func:`~semmatch.experiments.plan_networks.plan_networks`): under the v2 plan every training
    seed of each architecture shipped in ``shipped_dir`` (``compact``, ``compact@1`` ...), under v1
    the profile's as they are.

    Parameters
    ----------
    seeds : sequence of int
        Checked with :func:`~semmatch.experiments.protocol.check_confirm_seeds`.
    out : path
        The file to write.
    base_profile : str
    params_file : path
    shipped_dir : path, optional
        The shipped networks (default ``models/<base_profile>``).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        An unknown profile, refused seeds, or splits that break the protocol.
    """
    from .plan_networks import plan_networks

    data = read_params(params_file)
    profiles = data.get("profiles") or {}
    if base_profile not in profiles:
        raise ValueError(f"{params_file}: profile {base_profile!r} does not exist; valid profiles: "
                         f"{', '.join(sorted(profiles))}")
    seeds = check_confirm_seeds(seeds, profiles, where=str(params_file))
    _refuse_study_seeds(seeds)
    profile = copy.deepcopy(profiles[base_profile])
    common = profile["common"]
    common["eval_seeds"] = seeds
    if common.get("networks"):
        common["networks"] = plan_networks(common["networks"], plan_for_seeds(seeds),
                                           shipped_dir or ROOT / "models" / base_profile,
                                           default_seed=int(common.get("seed") or 0))
    check_protocol(profile["common"], where=f"confirmatory run on seeds {seeds}")
    header = (f"# Confirmatory run: profile {base_profile!r} of {Path(params_file).name} with eval_seeds = {seeds}\n"
              f"# (written by python -m semmatch.experiments confirm; not meant to be edited)\n")
    out = Path(out)
    atomic_write_text(out, header + yaml.safe_dump({"profile": base_profile, "profiles": {base_profile: profile}},
                                                   sort_keys=False, default_flow_style=None, width=120))
    return out


def unshipped_networks(params_file: str | os.PathLike, profile: str, data_root: str | os.PathLike,
                       shipped_dir: str | os.PathLike) -> dict[str, str]:
    """The networks of ``profile`` that ``shipped_dir`` does not hold trained with its configuration.

    Returns
    -------
    dict
        Network name -> why it is not shipped (empty: every network is).
    """
    from ..segment.shipping import shipped_checkpoint
    from ..segment.training import pipeline_configs

    p = notebook_parameters("02_train_segmentation", profile, params_file, data_root=str(data_root))
    configs = pipeline_configs(
        p["networks"], train_profile=p["train_profile"], seed=p["seed"], kinds=p["kinds"],
        train_seeds=p["train_seeds"], val_seeds=p["val_seeds"], eval_seeds=p["eval_seeds"], width=p["width"],
        height=p["height"], steps=p.get("steps"), out_dir=Path(data_root) / "models",
        cache_dir=Path(data_root) / "cache" / "segment")
    missing = {}
    for net, cfg in configs.items():
        path, why = shipped_checkpoint(cfg, shipped_dir)
        if path is None:
            missing[net] = why
    return missing


def _require_shipped(missing: dict[str, str], allow_training: bool, shipped_dir: Path) -> None:
    """Refuse networks that are not shipped (:func:`unshipped_networks`) unless ``allow_training``."""
    if missing and not allow_training:
        raise ValueError(
            "a confirmatory run uses the shipped networks, but "
            + "; ".join(f"{n}: {why}" for n, why in missing.items())
            + f". Restore {shipped_dir}/ from git, or pass --allow-training to train them (then it does not "
              f"confirm the shipped networks)")


def run_confirm(seeds: Sequence[int], *, name: str | None = None, base_profile: str = "full",
                allow_training: bool = False, params_file: str | os.PathLike = ROOT / "params.yaml",
                out_root: str | os.PathLike | None = None, log_output: bool = False,
                scheduler: str | None = None, in_home: bool = False,
                notebooks: Sequence[str] | None = None, when_transfer_pays: bool = False) -> dict:
    """Run every evaluation study of ``base_profile`` on the scenes of ``seeds``.

    Parameters
    ----------
    seeds : sequence of int
        Fresh scene seeds (each: one scene of every kind of the profile).
    name : str, optional
        Run name (default :func:`confirm_name`).
    base_profile : str
        The profile whose studies and settings are run (``full``).
    allow_training : bool
        Train the networks that are not shipped (a profile without shipped networks, e.g. the
        smoke test's); without it such a network is an error.
    params_file : path
    out_root : path, optional
        Where ``data/``, ``figures/`` and ``reports/`` go (default: the repository root).
    log_output : bool
        Stream the notebooks' output to the console.
    scheduler : str, optional
        Dask scheduler address for the per-scene tasks.
    in_home : bool
        Also run the in-home adaptation study (:func:`semmatch.experiments.in_home.run_in_home_study`,
        the committed ``in_home_plan.yaml``) in the homes of the run's scenes (its kinds x ``seeds``),
        with the shipped networks and the shipped across-homes adaptation; results in
        ``figures/confirm/<name>/in_home/``. Only with the plan's profile (``full``). The homes
        are those of the first ``in_home_max_seeds`` seeds (``adapt_plan.yaml``: 3, for the budget).
    notebooks : sequence of str, optional
        Run only these notebooks in an existing run of the same seeds and name (its data and
        ``confirm.json`` must be there; e.g. ``09_adapt_robot_view`` once adapted networks are
        shipped). The run's record keeps its earlier stages and lists this addition.
    when_transfer_pays : bool
        Also run the "when transfer pays" study (:func:`semmatch.experiments.when_transfer_pays.run_when_transfer_pays`,
        its committed grid) on the run's scenes, with the run's networks and person tours; results
        in ``figures/confirm/<name>/when_transfer_pays/`` (``make confirm`` passes it).

    Returns
    -------
    dict
        The run record written to ``figures/confirm/<name>/confirm.json``.

    Raises
    ------
    ValueError
        Refused seeds, or networks that are not shipped (without ``allow_training``); with
        ``in_home``, a base profile other than the in-home plan's or no shipped across-homes
        adaptation.
    NotebookFailed
        A notebook failed (naming it and the cell).
    """
    data = read_params(params_file)
    seeds = check_confirm_seeds(seeds, data.get("profiles") or {}, where=str(params_file))
    _refuse_study_seeds(seeds)
    plan = plan_for_seeds(seeds)  # v2 for the v2 plan's confirmatory seeds, else v1
    name = name or confirm_name(seeds)
    if not name.replace("-", "").replace("_", "").replace(".", "").isalnum():
        raise ValueError(f"run name {name!r}: use letters, digits, '-', '_' and '.' only")
    # relative to the repository root (the notebooks' working directory) unless out_root is given
    dirs = {k: str(Path(out_root or "") / sub / "confirm" / name)
            for k, sub in (("data_root", "data"), ("figures_dir", "figures"), ("reports_dir", "reports"))}
    where = {k: ROOT / v for k, v in dirs.items()}  # an absolute out_root stays as it is
    data_root = where["data_root"]
    in_home_plan = _check_in_home(base_profile) if in_home else None
    earlier = _earlier_record(where["figures_dir"], seeds, notebooks)
    before = (data_root / "params.yaml").read_text() if earlier and (data_root / "params.yaml").is_file() else None
    params = write_confirm_params(seeds, data_root / "params.yaml", base_profile=base_profile,
                                  params_file=params_file)
    if before is not None and params.read_text() != before:  # an addition runs with the run's own parameters
        atomic_write_text(params, before)
        raise ValueError(f"{params}: the parameters this code writes differ from those the run was made with; "
                         f"an addition (--notebooks) must use the run's parameters: make a new run instead")
    shipped_dir = Path("models") / base_profile
    missing = unshipped_networks(params, base_profile, dirs["data_root"], ROOT / shipped_dir)
    _require_shipped(missing, allow_training, shipped_dir)
    for d in where.values():
        d.mkdir(parents=True, exist_ok=True)
    print(f"[confirm] {name}: profile {base_profile}, seeds {seeds} x {len(data['profiles'][base_profile]['common']['kinds'])} "
        f"kinds; networks: " + (f"trained here ({', '.join(missing)})" if missing else f"shipped ({shipped_dir}/)"),
        file=sys.stderr)
    t0, walls = time.perf_counter(), {}
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    adapted_from = adapted_networks_source(ROOT / shipped_dir)
    skipped = {} if adapted_from else dict(SKIPPED)
    for nb in NOTEBOOKS:
        if notebooks is not None and nb not in notebooks:
            continue
        if nb in skipped:
            print(f"[confirm] {nb}: {skipped[nb]}", file=sys.stderr)
            continue
        extra = {"require_shipped": adapted_from == "shipped"} if nb == ADAPT_NOTEBOOK else {}
        t = time.perf_counter()
        run_notebook(nb, base_profile, params_file=params, reports_dir=dirs["reports_dir"], cwd=ROOT,
                     data_root=dirs["data_root"], figures_dir=dirs["figures_dir"], log_output=log_output,
                     scheduler=scheduler, **extra)
        walls[nb] = round(time.perf_counter() - t, 1)
    # every claim of the analysis plan judged on this run's per-scene tables (verdicts.csv/.md)
    from ..segment.shipping import file_sha256

    walls.update(_judge(where["figures_dir"], [nb for nb in NOTEBOOKS if nb not in skipped
                                               and (notebooks is None or nb in notebooks)], plan, params))
    if in_home_plan is not None:
        from .adapt_claims import load_adapt_plan
        from .in_home import run_in_home_study

        t = time.perf_counter()
        home_seeds = list(seeds)[:load_adapt_plan().in_home_max_seeds]
        homes = [(kind, s) for s in home_seeds for kind in in_home_plan.kinds]
        print(f"[confirm] in-home study: {len(homes)} homes (seeds {home_seeds} x {len(in_home_plan.kinds)} kinds)",
              file=sys.stderr)
        jobs = int((data["profiles"][base_profile].get("common") or {}).get("jobs", 1))
        run_in_home_study(data_root / "in_home", where["figures_dir"] / "in_home", homes=homes, jobs=jobs,
                          scheduler=scheduler, progress=log_output, analysis_plan=plan)
        walls["in_home"] = round(time.perf_counter() - t, 1)
    walls.update(_when_transfer_pays(when_transfer_pays, seeds, data, base_profile, where, scheduler, log_output))

    models = data_root / "models"
    record = {
        "name": name, "base_profile": base_profile, "seeds": seeds,
        "kinds": data["profiles"][base_profile]["common"]["kinds"],
        "networks": {p.stem: file_sha256(p) for p in sorted(models.glob("*.pt"))},
        "networks_from": "trained here" if missing else str(shipped_dir),
        "adapted_networks_from": (f"{shipped_dir}/adapted" if adapted_from == "shipped" else adapted_from) or "skipped",
        "skipped": skipped, "in_home": in_home_plan is not None, "code_version": code_version(), "started": started,
        "analysis_plan": _plan_record(plan, where["figures_dir"]),
        "wall_seconds": walls, "total_seconds": round(time.perf_counter() - t0, 1),
    }
    if earlier is not None:
        record = _with_addition(earlier, record, notebooks)
    atomic_write_text(where["figures_dir"] / "confirm.json", json.dumps(record, indent=2) + "\n")
    print(f"[confirm] {name}: done in {(time.perf_counter() - t0) / 60:.1f} min -> {dirs['figures_dir']}", file=sys.stderr)
    return record


def _when_transfer_pays(run: bool, seeds: Sequence[int], data: dict, base_profile: str, where: dict[str, Path],
                        scheduler: str | None, progress: bool) -> dict[str, float]:
    """The "when transfer pays" study on every kind of every seed of the run (when ``run``), with the
    run's data root (person tours, networks); results in ``<figures_dir>/when_transfer_pays``. Returns
    its wall seconds as ``{"when_transfer_pays": s}`` (``{}`` when not run)."""
    if not run:
        return {}
    from .when_transfer_pays import run_when_transfer_pays

    t = time.perf_counter()
    common = data["profiles"][base_profile]["common"]
    run_when_transfer_pays(where["data_root"], where["figures_dir"] / "when_transfer_pays",
                           [(kind, s) for s in seeds for kind in common["kinds"]], split="eval",
                           jobs=int(common.get("jobs", 1)), scheduler=scheduler, progress=progress,
                           method_settings=run_method_settings(common))
    return {"when_transfer_pays": round(time.perf_counter() - t, 1)}


def _judge(figures_dir: Path, ran: Sequence[str], plan: AnalysisPlan, params_file: Path) -> dict[str, float]:
    """The analysis plan's verdicts on the paper's claims, unless only stage 09 ran (it judges
    the adaptation claims itself: ``adapt_verdicts.md``).

    ``plan`` is the run's (:func:`~semmatch.experiments.analysis_plan.plan_for_seeds`). Under a v2
    plan the per-scene tables first get their ``training_seed`` column
    (:func:`~semmatch.experiments.plan_networks.label_training_seeds`) and the plan's speed
    benchmark runs once per run, in a fresh process after the notebooks
    (:func:`~semmatch.experiments.speed_claims.run_speed_bench`: ``bench_speed.json``, which
    :func:`~semmatch.experiments.claims.judge_figures` judges P1-P3 on), with the plan's speed
    lever as the run's ``params_file`` states it. Returns the wall seconds
    of ``verdicts`` (and ``speed_bench`` when it ran).
    """
    from .claims import judge_figures
    from .plan_networks import label_training_seeds
    from .speed_claims import BENCH_RECORD, lever_settings, run_speed_bench

    walls = {}
    if set(ran) - {ADAPT_NOTEBOOK} and plan.rules == "v2":
        label_training_seeds(figures_dir)
        if not (figures_dir / BENCH_RECORD).is_file():  # once per run: an addition keeps the first measurement
            t = time.perf_counter()
            lever = lever_settings(plan, read_params(params_file), where=str(params_file))
            run_speed_bench(figures_dir, plan, cwd=ROOT, settings=lever)
            walls["speed_bench"] = round(time.perf_counter() - t, 1)
    t = time.perf_counter()
    if set(ran) - {ADAPT_NOTEBOOK}:
        judge_figures(figures_dir, plan=plan)
    return {**walls, "verdicts": round(time.perf_counter() - t, 1)}


def _plan_record(plan: AnalysisPlan, figures_dir: Path) -> dict:
    """The run record's ``analysis_plan``: the plan file, version and rules that judged the run, and
    under a v2 plan the speed benchmark's conditions (machine, load, reference rate)."""
    from .speed_claims import BENCH_RECORD, bench_conditions

    record = {"file": PLAN_V2_FILE.name if plan.version == 2 else PLAN_FILE.name, "version": plan.version,
              "rules": plan.rules}
    bench = figures_dir / BENCH_RECORD
    if plan.rules == "v2" and bench.is_file():
        record["speed_bench"] = {"record": BENCH_RECORD, **bench_conditions(json.loads(bench.read_text()))}
    return record


def _with_addition(earlier: dict, record: dict, notebooks: Sequence[str] | None) -> dict:
    """An existing run's record with this run (``notebooks`` added to it) listed under ``additions``;
    the first record's stages, times and code version stay."""
    addition = {k: record[k] for k in ("code_version", "started", "wall_seconds", "total_seconds",
                                       "adapted_networks_from", "in_home")}
    return {**earlier, "networks": record["networks"], "adapted_networks_from": record["adapted_networks_from"],
            "skipped": {k: v for k, v in earlier.get("skipped", {}).items() if k not in (notebooks or ())},
            "in_home": earlier.get("in_home", False) or record["in_home"],
            "additions": [*earlier.get("additions", []), {"notebooks": list(notebooks or ()), **addition}]}


def _earlier_record(figures_dir: Path, seeds: Sequence[int], notebooks: Sequence[str] | None) -> dict | None:
    """The existing run's record that ``notebooks`` add to (None without ``notebooks``); ValueError
    when there is no such run or it was made on other seeds, or a notebook name is unknown."""
    if notebooks is None:
        return None
    unknown = sorted(set(notebooks) - set(NOTEBOOKS))
    if unknown:
        raise ValueError(f"--notebooks: unknown notebook(s) {unknown}; valid: {', '.join(NOTEBOOKS)}")
    rec = figures_dir / "confirm.json"
    if not rec.is_file():
        raise ValueError(f"--notebooks adds to an existing confirmatory run, but {rec} does not exist; "
                         f"run make confirm without --notebooks first")
    earlier = json.loads(rec.read_text())
    if sorted(int(s) for s in earlier.get("seeds", [])) != sorted(seeds):
        raise ValueError(f"{rec}: that run used seeds {earlier.get('seeds')}, not {list(seeds)}")
    return earlier


def _refuse_study_seeds(seeds: Sequence[int]) -> None:
    """Refuse the seeds of the side studies' scenes: the in-home study's homes and the held-out
    adaptation scenes (:data:`semmatch.experiments.adapt_studies.HELDOUT_ADAPT_SEEDS`); they were
    generated and scored there."""
    from .adapt_studies import HELDOUT_ADAPT_SEEDS
    from .in_home import PLAN_PATH, load_in_home_plan

    used = sorted(set(seeds) & set(load_in_home_plan().seeds))
    if used:
        raise ValueError(f"{PLAN_PATH.name}: refusing confirmatory seeds {used}: they are the in-home study's homes "
                         f"(every kind generated and scored there); choose seeds nobody has used")
    used = sorted(set(seeds) & set(HELDOUT_ADAPT_SEEDS))
    if used:
        raise ValueError(f"refusing confirmatory seeds {used}: they are held-out adaptation scenes "
                         f"(scripts/adapt_heldout.py, docs/adapt.md); choose seeds nobody has used")


def _check_in_home(base_profile: str):
    """The in-home plan, when a confirmatory run of ``base_profile`` can run it (else ValueError, naming why)."""
    from .in_home import load_in_home_plan

    plan = load_in_home_plan()
    if plan.profile != base_profile:
        raise ValueError(f"--in-home: the in-home plan uses the networks of profile {plan.profile!r} "
                         f"(models/{plan.profile}/), not {base_profile!r}")
    across = ROOT / "models" / plan.profile / "adapted" / f"{plan.across_homes}.pt"
    if not across.is_file():
        raise ValueError(f"--in-home: {across} (the shipped across-homes adaptation) is missing; restore it from git")
    return plan


def add_confirm_parser(sub) -> None:
    """The ``confirm`` subcommand of ``python -m semmatch.experiments``."""
    c = sub.add_parser("confirm", help="every evaluation study on fresh scenes with the shipped networks "
                                       "(make confirm SEEDS=...)")
    c.add_argument("--seeds", nargs="+", required=True, help="fresh scene seeds (each: one scene of every kind)")
    c.add_argument("--name", help="run name: figures/confirm/NAME/ (default seeds-...)")
    c.add_argument("--base-profile", default="full", help="profile whose studies are run (default full)")
    c.add_argument("--allow-training", action="store_true",
                   help="train networks that are not shipped (for profiles without shipped networks)")
    c.add_argument("--params", default=str(ROOT / "params.yaml"))
    c.add_argument("--quiet", action="store_true", help="do not stream the notebooks' output")
    c.add_argument("--scheduler", help="Dask scheduler address for the per-scene tasks")
    c.add_argument("--in-home", action="store_true",
                   help="also run the in-home adaptation study in the run's homes (docs/adapt.md)")
    c.add_argument("--when-transfer-pays", action="store_true",
                   help="also run the 'when transfer pays' study on the run's scenes (docs/when_transfer_pays.md)")
    c.add_argument("--notebooks", nargs="+", metavar="NOTEBOOK",
                   help="run only these notebooks in an existing run of the same seeds (e.g. 09_adapt_robot_view)")
    c.set_defaults(handler=_confirm_main)


def _confirm_main(args) -> int:
    run_confirm(args.seeds, name=args.name, base_profile=args.base_profile, allow_training=args.allow_training,
                params_file=args.params, log_output=not args.quiet, scheduler=args.scheduler, in_home=args.in_home,
                notebooks=args.notebooks, when_transfer_pays=args.when_transfer_pays)
    return 0


def add_ship_parser(sub) -> None:
    """The ``ship`` subcommand: copy trained checkpoints into ``models/<profile>/`` with manifests."""
    s = sub.add_parser("ship", help="copy trained networks into a shipped folder (models/<profile>/) with manifests")
    s.add_argument("--models", required=True, help="folder of the trained checkpoints (data/<profile>/models)")
    s.add_argument("--to", required=True, help="the shipped folder, e.g. models/full")
    s.add_argument("--networks", nargs="+", default=["compact", "strong"])
    s.add_argument("--code-version", help="the commit the networks were trained with (default: git describe of "
                                          "this checkout, right when shipping right after training)")
    s.add_argument("--note", help="free text recorded in each manifest (e.g. how busy the machine was)")
    s.set_defaults(handler=_ship_main)


def _ship_main(args) -> int:
    from ..segment.shipping import ship_networks

    src = Path(args.models)
    missing = [n for n in args.networks if not (src / f"{n}.pt").is_file()]
    if missing:
        raise FileNotFoundError(f"{src}: no checkpoint for {', '.join(missing)}")
    for p in ship_networks({n: src / f"{n}.pt" for n in args.networks}, args.to, recipe=src / "recipe.json",
                           code_version=args.code_version or code_version(), note=args.note):
        print(p)
    return 0


def add_ship_adapted_parser(sub) -> None:
    """The ``ship-adapted`` subcommand: copy stage 09's adapted networks into ``models/<profile>/adapted/``."""
    s = sub.add_parser("ship-adapted", help="copy a run's adapted networks and recipe choice into a shipped folder "
                                            "(models/<profile>/adapted/) with a manifest")
    s.add_argument("--profile", help="profile whose notebook 09 parameters the run used (default: params.yaml's)")
    s.add_argument("--data-root", help="the run's data root (default data/<profile>)")
    s.add_argument("--figures-dir", help="the run's figures (default figures/<profile>): its validation_adapt_recipe.csv")
    s.add_argument("--to", help="the shipped folder (default models/<profile>/adapted)")
    s.add_argument("--code-version", help="the commit the run fine-tuned with (default: git describe of this checkout)")
    s.add_argument("--note", help="free text recorded in the manifest")
    s.add_argument("--seed", type=int, default=None,
                   help="ship another fine-tuning seed of the same request and recipe (analysis plan v2), from "
                        "--checkpoints, into models/<profile>/adapted@SEED (default: notebook 09's own seed)")
    s.add_argument("--checkpoints", help="folder of that seed's <network>~<source>.pt (default <data-root>/adapted)")
    s.add_argument("--trained-on", default="CPU (notebook 09 of a make repro run)",
                   help="where the fine-tuning ran, recorded in the manifest")
    s.set_defaults(handler=_ship_adapted_main)


def _ship_adapted_main(args) -> int:
    from .finetune_seeds import seed_folder
    from .shipped_adaptation import RECIPE_TABLE, ship_adaptation

    params = notebook_parameters("09_adapt_robot_view", args.profile)
    name = params["profile"]
    figures = Path(args.figures_dir or ROOT / "figures" / name)
    seed = params["seed"] if args.seed is None else args.seed
    if seed < 0:
        raise SystemExit(f"ship-adapted: --seed must be >= 0, got {seed}")
    dest = args.to or seed_folder(ROOT / "models" / name / "adapted", seed, base_seed=params["seed"])
    for p in ship_adaptation(args.data_root or ROOT / "data" / name, params["network"], dest,
                             parameters={**params, "seed": seed}, recipe_table=figures / RECIPE_TABLE,
                             code_version=args.code_version or code_version(), note=args.note,
                             checkpoints_dir=args.checkpoints, trained_on=args.trained_on):
        print(p)
    return 0
