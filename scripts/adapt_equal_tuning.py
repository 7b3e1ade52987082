"""Equal tuning (issue 38 item 3): a label source's own adaptation recipe, chosen on validation.

Stage 09's recipe (lr 4e-3, half of each batch human-height, 1600 steps) was chosen in validation
diagnostics run with `3d-neighborhood` labels, and self-training then reused it: the baseline got
a recipe tuned for its rival. Here a source gets its own recipe by the stage's rule
(``choose_adaptation_recipe``: among the candidates that lose at most 0.02 mIoU at 1.6 m on the
validation sweeps, the largest gain at 0.2 m), from the candidates of the ``large`` profile's
``recipe_grid`` (params.yaml, declared before this study: lr 4e-3 / 3e-4 x share 0.5 / 0.75),
each with the stage's other settings (steps, batch, seed). The candidate equal to the stage's
recipe is the stage's own checkpoint (``DATA/adapted/``, checked). When a source's choice differs
from the stage's recipe, its chosen network is scored on the development evaluation sweeps beside
the stage's network of that source, as notebook 09 scores them. Nothing here changes the stage.
Two phases::

    python scripts/adapt_equal_tuning.py finetune [--sources self-training] [--data-root DIR] [--out DIR]
    python scripts/adapt_equal_tuning.py score    [--sources self-training] [--data-root DIR] [--out DIR] [--figures DIR]

The robot views come from ``scripts/adapt_seeds.py prepare`` (``<data-root>_adapt_seeds/robot_views.pkl``);
checkpoints go to ``--out`` (default ``<data-root>_adapt_equal``), tables to ``--figures``
(default ``figures/<profile>_adapt_equal``).
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import pandas as pd

#: the recipe fields a candidate may set; the others come from the stage's recipe
GRID_FIELDS = ("lr", "upper_share", "distill")


def trials(p) -> tuple[list[dict], int]:
    """The candidates (the stage's recipe with the large grid's fields) and the index of the one
    equal to the stage's own recipe (-1 when the grid lacks it)."""
    from semmatch.experiments.adapt import recipe_candidates
    from semmatch.experiments.adapt_studies import stage_recipe
    from semmatch.experiments.pipeline import notebook_parameters

    try:
        stage = stage_recipe(p["figures_dir"]).as_dict()
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(str(e)) from None
    grid = notebook_parameters("09_adapt_robot_view", "large", data_root=p["data_root"])["recipe_grid"]
    out, same = [], -1
    for i, c in enumerate(recipe_candidates(grid)):
        t = {**stage, **{k: c.get(k, stage[k]) for k in GRID_FIELDS}}
        if all(float(t[k]) == float(stage[k]) for k in GRID_FIELDS):
            same = i
        out.append(t)
    return out, same


def _checkpoint(args, p, source: str, i: int, same: int) -> Path:
    from semmatch.segment.adapt import adapted_name

    if i == same:
        return Path(p["data_root"]) / "adapted" / f"{adapted_name(p['network'], source)}.pt"
    return args.out / source / f"candidate{i}.pt"


def finetune(args, p) -> None:
    from semmatch.experiments.layout import Layout
    from semmatch.segment.adapt import fine_tune

    robot, _ = pickle.loads(args.views.read_bytes())  # written by scripts/adapt_seeds.py prepare
    cands, same = trials(p)
    for source in args.sources:
        for i, kw in enumerate(cands):
            path = _checkpoint(args, p, source, i, same)
            if path.is_file():
                print(f"{source} candidate {i}: {path} exists", flush=True)
                continue
            t = time.perf_counter()
            path.parent.mkdir(parents=True, exist_ok=True)
            fine_tune(Layout(p["data_root"]).model(p["network"]), robot, source, path, progress=False, **kw)
            print(f"{source} candidate {i} ({kw}): {time.perf_counter() - t:.0f} s", flush=True)


def _check_stage_checkpoint(path: Path, recipe: dict, source: str) -> None:
    from semmatch.segment import load_model

    rec = load_model(path).info.get("adapted", {})
    bad = [k for k in recipe if k in rec and float(rec[k]) != float(recipe[k])]
    if rec.get("label_source") != source or bad:
        raise SystemExit(f"{path}: not {source} with the stage's recipe (differs in {bad or 'label_source'})")


def score(args, p) -> None:
    from semmatch.experiments.adapt import (
        adapted_height_study,
        gap_bounds,
        gap_table,
        score_recipe_candidates,
    )
    from semmatch.experiments.tables import save_table
    from semmatch.segment.adapt import adapted_name

    cands, same = trials(p)
    tables, per_scene, gaps, bounds = [], [], [], []
    for source in args.sources:
        paths = [_checkpoint(args, p, source, i, same) for i in range(len(cands))]
        missing = [str(x) for x in paths if not x.is_file()]
        if missing:
            raise SystemExit(f"run the finetune phase first: missing {', '.join(missing)}")
        if same >= 0:
            _check_stage_checkpoint(paths[same], cands[same], source)
        table = score_recipe_candidates(p["data_root"], p["network"], cands, paths, source=source,
                                        max_forgetting=p["max_forgetting"], jobs=p["jobs"])
        table["stage_recipe"] = table["candidate"] == same
        tables.append(table)
        pick = int(table.loc[table["chosen"], "candidate"].iloc[0])
        print(table[["candidate", "lr", "upper_share", "gain_low", "change_high", "gap_closed", "chosen"]]
              .round(3).to_string(), flush=True)
        if pick == same:
            print(f"{source}: its own choice is the stage's recipe; nothing more to score", flush=True)
            continue
        name = adapted_name(p["network"], source)
        ps = adapted_height_study(p["data_root"], p["network"], {name: paths[same], f"{name} (own recipe)": paths[pick]},
                                  frame_step=p["sweep_frame_step"], jobs=p["jobs"])
        per_scene.append(ps)
        gaps.append(gap_table(ps, p["network"]))
        bounds.append(gap_bounds(ps, p["network"]))
    figures = args.figures or Path(f"{p['figures_dir']}_adapt_equal")
    save_table(pd.concat(tables, ignore_index=True), figures, "equal_tuning_validation")
    if gaps:
        save_table(pd.concat(per_scene, ignore_index=True), figures, "equal_tuning_height_per_scene")
        save_table(pd.concat(gaps, ignore_index=True).drop_duplicates("model"), figures, "equal_tuning_gap")
        save_table(pd.concat(bounds, ignore_index=True).drop_duplicates("model"), figures, "equal_tuning_bounds")
    print(f"tables in {figures}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("phase", choices=["finetune", "score"])
    ap.add_argument("--profile", default=None, help="profile of params.yaml (default: its 'profile')")
    ap.add_argument("--data-root", type=Path, default=None, help="the pipeline's data root (default: the profile's)")
    ap.add_argument("--sources", nargs="+", default=["self-training"], help="label sources (default: self-training)")
    ap.add_argument("--views", type=Path, default=None,
                    help="robot views of scripts/adapt_seeds.py prepare (default <data-root>_adapt_seeds/robot_views.pkl)")
    ap.add_argument("--out", type=Path, default=None, help="candidate checkpoints (default <data-root>_adapt_equal)")
    ap.add_argument("--figures", type=Path, default=None, help="tables")
    args = ap.parse_args()
    from semmatch.experiments.adapt_studies import stage_parameters

    p = stage_parameters(args.profile, args.data_root)
    root = Path(p["data_root"])
    args.views = args.views or root.with_name(root.name + "_adapt_seeds") / "robot_views.pkl"
    args.out = args.out or root.with_name(root.name + "_adapt_equal")
    if args.phase == "finetune" and not args.views.is_file():
        raise SystemExit(f"{args.views}: run `python scripts/adapt_seeds.py prepare` first")
    {"finetune": finetune, "score": score}[args.phase](args, p)


if __name__ == "__main__":
    main()
