"""The experiment pipeline: profiles, notebook hygiene, failure messages."""

from __future__ import annotations

import json
import re
from pathlib import Path

import nbformat
import pytest

from semmatch.experiments import paper, pipeline, tables

ROOT = Path(__file__).resolve().parents[1]


def test_unknown_profile_is_refused_with_the_valid_ones():
    with pytest.raises(ValueError, match=r"profile 'nope' does not exist; valid profiles: full, large, smoke"):
        pipeline.load_params(ROOT / "params.yaml", "nope")


def test_notebook_parameters_merge_common_and_section():
    p = pipeline.notebook_parameters("01_simulate", "smoke")
    assert p["profile"] == "smoke" and p["data_root"] == "data/smoke"
    assert "n_frames_lower" in p and "eval_seeds" in p


@pytest.mark.parametrize("name", pipeline.NOTEBOOKS)
def test_notebooks_are_committed_clean_with_a_parameters_cell(name):
    nb = json.loads((ROOT / "notebooks" / f"{name}.ipynb").read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert not any(c.get("outputs") for c in code), f"{name} has outputs"
    assert any("parameters" in c.get("metadata", {}).get("tags", []) for c in code), f"{name}: no parameters cell"
    assert any(c["cell_type"] == "markdown" for c in nb["cells"]), f"{name}: no narrative"


def test_failing_notebook_names_cell_and_parameters(tmp_path):
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    params = nbformat.v4.new_code_cell("seed = 1\nprofile = \"full\"")
    params.metadata["tags"] = ["parameters"]
    nb.cells = [params, nbformat.v4.new_code_cell("x = 1"), nbformat.v4.new_code_cell("raise RuntimeError('boom')")]
    (tmp_path / "nb").mkdir()
    nbformat.write(nb, tmp_path / "nb" / "01_simulate.ipynb")
    (tmp_path / "params.yaml").write_text(
        "profile: smoke\nprofiles:\n  smoke:\n    common: {seed: 0, unused: 3}\n    simulate: {}\n"
    )
    with pytest.raises(pipeline.NotebookFailed) as e:
        pipeline.run_notebook("01_simulate", "smoke", notebooks_dir=tmp_path / "nb", params_file=tmp_path / "params.yaml",
                              reports_dir=tmp_path / "rep", cwd=tmp_path)
    msg = str(e.value)
    assert "01_simulate failed in cell" in msg and "RuntimeError: boom" in msg
    assert "'profile': 'smoke'" in msg and "'seed': 0" in msg and "unused" not in msg


def test_cell_output_streams_to_the_console_while_the_notebook_runs(tmp_path, caplog):
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    params = nbformat.v4.new_code_cell("seed = 1\nprofile = None")
    params.metadata["tags"] = ["parameters"]
    nb.cells = [params, nbformat.v4.new_code_cell("print('step 7 of 9: loss 0.25')")]
    (tmp_path / "nb").mkdir()
    nbformat.write(nb, tmp_path / "nb" / "01_simulate.ipynb")
    (tmp_path / "params.yaml").write_text("profile: smoke\nprofiles:\n  smoke:\n    common: {seed: 0}\n    simulate: {}\n")
    kw = dict(notebooks_dir=tmp_path / "nb", params_file=tmp_path / "params.yaml", reports_dir=tmp_path / "rep",
              cwd=tmp_path)
    with caplog.at_level("INFO", logger="papermill"):
        pipeline.run_notebook("01_simulate", "smoke", log_output=True, **kw)
    assert "step 7 of 9: loss 0.25" in caplog.text
    caplog.clear()
    with caplog.at_level("INFO", logger="papermill"):
        pipeline.run_notebook("01_simulate", "smoke", **kw)  # quiet by default (library use, tests)
    assert "step 7 of 9" not in caplog.text


def test_parameter_the_notebook_does_not_declare_is_refused(tmp_path):
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    params = nbformat.v4.new_code_cell("seed = 1")
    params.metadata["tags"] = ["parameters"]
    nb.cells = [params]
    (tmp_path / "nb").mkdir()
    nbformat.write(nb, tmp_path / "nb" / "01_simulate.ipynb")
    (tmp_path / "params.yaml").write_text("profiles:\n  smoke:\n    simulate: {n_framez: 3}\n")
    with pytest.raises(ValueError, match="gives n_framez, which the notebook's parameters cell does not declare"):
        pipeline.run_notebook("01_simulate", "smoke", notebooks_dir=tmp_path / "nb",
                              params_file=tmp_path / "params.yaml", reports_dir=tmp_path / "rep", cwd=tmp_path)


def test_findings_are_checked_on_numbers():
    import pandas as pd

    rows = [
        ("compact", "upper", 0.80), ("compact", "lower", 0.70),
        ("compact", "3d-neighborhood", 0.79), ("compact", "2d-slic", 0.75),
        ("ground truth", "3d-neighborhood", 0.95), ("ground truth", "2d-slic", 0.96),
    ]
    df = pd.DataFrame([dict(model=m, method=k, mean_acc=v) for m, k, v in rows])
    f = {x.statement: x.holds for x in tables.check_findings(df, ["2d-slic", "3d-neighborhood"])}
    assert f["label transfer beats the lower-view network"] is True
    assert f["3D neighbourhood has the best Mean Acc."] is False  # GT: 2d-slic wins here
    assert f["the lower-view network is worse than the upper-view one"] is True


def test_paper_columns_are_matched():
    import pandas as pd

    df = pd.DataFrame([dict(model="strong", method="3d-neighborhood", mean_acc=0.8)])
    out = tables.with_paper_columns(df, 2)
    assert out["paper_mean_acc"].iloc[0] == paper.TABLE2[("transfiner", "3d-neighborhood")][3]


def test_readme_results_section_is_generated_from_figures(tmp_path):
    from semmatch.experiments import readme

    fig = tmp_path / "figures" / "full"
    fig.mkdir(parents=True)
    (fig / "table2_synthetic.md").write_text("| a |\n|---|\n| 1 |\n")
    (fig / "table2_synthetic.png").write_bytes(b"png")
    r = tmp_path / "README.md"
    r.write_text(f"# x\n{readme.BEGIN}\nold\n{readme.END}\nrest\n")
    assert readme.update_readme(r, fig)
    text, doc = r.read_text(), (tmp_path / "docs" / "results.md").read_text()
    # the README's headline: the figure and a link; the results document: every table
    assert "old" not in text and "](figures/full/table2_synthetic.png)" in text and "](docs/results.md)" in text
    assert "| 1 |" in doc and "](../figures/full/table2_synthetic.png)" in doc
    assert text.endswith("rest\n") and not readme.update_readme(r, fig)
    assert "Training variance" not in doc
    var = tmp_path / "figures" / "variance"
    var.mkdir()
    (var / "table2_training_seeds.md").write_text("| arch | mean |\n|---|---|\n")  # header only: not shown
    assert not readme.update_readme(r, fig)
    (var / "fig3_training_seeds.md").write_text("| arch | height | mean |\n|---|---|---|\n| compact | 0.2 | 0.5 |\n")
    assert readme.update_readme(r, fig)
    text = (tmp_path / "docs" / "results.md").read_text()
    assert "Training variance" in text and "| compact | 0.2 | 0.5 |" in text and "arch | mean" not in text
    import pandas as pd

    pd.DataFrame({"claim": ["C1"] * 2 + ["C2"] * 2, "data": "synthetic", "measure": "mean_acc",
                  "comparison": ["a - b"] * 2 + ["c - d"] * 2, "model": ["compact", "compact@1"] * 2,
                  "verdict": ["holds", "holds", "holds", "not resolved"]}).to_csv(var / "claims_synthetic.csv")
    assert readme.update_readme(r, fig)
    assert "1 of 2 comparisons get the same verdict with every seed; they differ for C2 c - d (mean_acc: holds, " \
           "not resolved)." in (tmp_path / "docs" / "results.md").read_text()
    # the profile's training-seed study, once it has run, stands instead of the older variance profile
    seeds = tmp_path / "figures" / "full_training_seeds"
    seeds.mkdir()
    (seeds / "training_seeds_table3.md").write_text("| model | method | seed 0 |\n|---|---|---|\n| strong | lower | 0.8 |\n")
    (seeds / "training_seeds.png").write_bytes(b"png")
    assert readme.update_readme(r, fig)
    doc = (tmp_path / "docs" / "results.md").read_text()
    assert "Training seeds (from" in doc and "| strong | lower | 0.8 |" in doc and "Training variance" not in doc
    assert "](../figures/full_training_seeds/training_seeds.png)" in doc


def test_readme_headline_comes_from_the_plans_confirmatory_run(tmp_path):
    import json

    from semmatch.experiments import readme

    plan = {"scenes": {"confirmatory_seeds": [8001, 8002]}}
    figs = tmp_path / "figures"
    dev = figs / "full"
    dev.mkdir(parents=True)
    (dev / "table2_synthetic.md").write_text("| dev |\n|---|\n| 1 |\n")
    assert readme.confirmatory_run(figs, plan) is None
    record = {"name": "mine", "seeds": [8002, 8001], "kinds": ["a", "b"], "networks_from": "models/full",
              "code_version": "abc1234", "started": "2026-11-26T15:00:00Z", "total_seconds": 600.0}
    for name, change in (("other-seeds", {"seeds": [9001, 9002]}), ("trained", {"networks_from": "trained here"}),
                         ("mine", {})):
        (figs / "confirm" / name).mkdir(parents=True)
        (figs / "confirm" / name / "confirm.json").write_text(json.dumps({**record, **change}))
    run = readme.confirmatory_run(figs, plan)
    assert run == figs / "confirm" / "mine"  # not a run on other seeds, not one that retrained the networks
    (run / "table2_synthetic.md").write_text("| confirm |\n|---|\n| 2 |\n")
    r = tmp_path / "README.md"
    r.write_text(f"# x\n{readme.BEGIN}\nold\n{readme.END}\n")
    assert readme.update_readme(r, dev, confirmatory_dir=run, judge=False)
    text = r.read_text()
    confirm_doc = (tmp_path / "docs" / "results_confirmatory.md").read_text()
    assert "Confirmatory run `mine`: scene seeds 8002, 8001 x 2 kinds (4 scenes" in text
    assert "](docs/results_confirmatory.md)" in text and "](docs/results.md)" in text
    assert "| confirm |" in confirm_doc and "make confirm" in confirm_doc and "| dev |" not in confirm_doc
    assert "| dev |" in (tmp_path / "docs" / "results.md").read_text()
    assert not readme.update_readme(r, dev, confirmatory_dir=run, judge=False)
    from semmatch.experiments.analysis_plan import load_analysis_plan

    assert readme.confirmatory_run(figs, load_analysis_plan()) is None  # the committed plan's seeds: 8001-8006


def test_protocol_refuses_bad_splits_before_any_work(tmp_path):
    from semmatch.experiments.protocol import check_protocol

    good = dict(kinds=["living_room", "bedroom"], train_seeds=[1, 2], val_seeds=[501, 502, 503, 504],
                eval_seeds=[7001], dev_seeds=[1001], min_val_per_kind=2)
    check_protocol(good)
    for bad, msg in [
        (dict(eval_seeds=[]), "eval_seeds is empty"),
        (dict(eval_seeds=[2]), "train and eval seeds must be disjoint"),
        (dict(val_seeds=[501, 502, 503, 1]), "train and val"),
        (dict(eval_seeds=[1001]), "looked at during development"),
        (dict(val_seeds=[501, 502, 503]), r"validation needs >= 2 scene\(s\) of every kind"),
        (dict(kinds=["castle"]), "unknown scene kind"),
    ]:
        with pytest.raises(ValueError, match=msg):
            check_protocol({**good, **bad})
    # the pipeline checks before it executes anything
    (tmp_path / "params.yaml").write_text(
        "profile: p\nprofiles:\n  p:\n    common: {kinds: [bedroom], train_seeds: [1], val_seeds: [2], eval_seeds: [1]}\n"
        "    simulate: {}\n")
    with pytest.raises(ValueError, match="disjoint"):
        pipeline.run_notebook("01_simulate", "p", params_file=tmp_path / "params.yaml", reports_dir=tmp_path / "rep",
                              cwd=tmp_path)
    assert not (tmp_path / "rep" / "01_simulate.ipynb").exists()


def test_full_profile_follows_the_protocol():
    from semmatch.experiments.protocol import check_protocol, validation_kinds

    full = pipeline.load_params(ROOT / "params.yaml", "full")["common"]
    check_protocol(full)
    assert len(full["eval_seeds"]) * len(full["kinds"]) >= 12
    assert min(validation_kinds(full["kinds"], full["val_seeds"]).values()) >= 2
    assert not set(full["eval_seeds"]) & set(full["dev_seeds"])
    large = pipeline.load_params(ROOT / "params.yaml", "large")["common"]
    check_protocol(large)
    assert len(large["eval_seeds"]) * len(large["kinds"]) >= 64
    assert not set(large["eval_seeds"]) & set(full["eval_seeds"])  # its own untouched scenes


def test_dvc_yaml_is_the_generators_output(tmp_path):
    import subprocess
    import sys

    root = pipeline.ROOT
    subprocess.run([sys.executable, str(root / "scripts" / "dvc_stages.py"), str(tmp_path / "dvc.yaml")], check=True)
    assert (tmp_path / "dvc.yaml").read_text() == (root / "dvc.yaml").read_text(), \
        "dvc.yaml was edited by hand: change scripts/dvc_stages.py and regenerate"


def test_every_stage_depends_on_its_notebook_and_its_modules():
    import yaml

    from semmatch.experiments.stagedeps import stage_modules

    stages = yaml.safe_load((pipeline.ROOT / "dvc.yaml").read_text())["stages"]
    by_notebook = {st["cmd"].split()[-1]: st for st in stages.values()}
    assert set(by_notebook) == set(pipeline.NOTEBOOKS)
    for nb, st in by_notebook.items():
        assert f"notebooks/{nb}.ipynb" in st["deps"] and set(stage_modules(nb)) <= set(st["deps"])


def test_stage_metrics_are_declared_and_written(tmp_path):
    import yaml

    from semmatch.experiments.headline import STAGE_METRICS, write_stage_metrics

    dvc = yaml.safe_load((pipeline.ROOT / "dvc.yaml").read_text())
    stage_files = {next(iter(o)) if isinstance(o, dict) else o for st in dvc["stages"].values() for o in st["outs"]}
    assert {f"figures/${{profile}}/metrics/{s}.json" for s in STAGE_METRICS} <= stage_files
    # one metrics file: `dvc metrics show` is one row, not a stage per row and a dash per other stage's number
    assert not [st for st in dvc["stages"].values() if st.get("metrics")]
    assert dvc["metrics"] == ["figures/${profile}/metrics.json"]
    (tmp_path / "table2_synthetic.csv").write_text(
        "model,method,scenes,mean_acc\nground truth,3d-neighborhood,12,0.93\ncompact,lower,12,0.8\ncompact,2d-slic,12,0.7\n")
    path = write_stage_metrics(tmp_path, "evaluate_synthetic")
    assert json.loads(path.read_text()) == {"table2.ground_truth.3d-neighborhood.mean_acc": 0.93,
                                            "table2.compact.lower.mean_acc": 0.8}
    assert write_stage_metrics(tmp_path, "qualitative") is None
    (tmp_path / "metrics" / "panoptic.json").write_text('{"panoptic.oracle.pq_things": 0.7}')
    write_stage_metrics(tmp_path, "evaluate_synthetic")  # gathers every stage's file
    assert json.loads((tmp_path / "metrics.json").read_text()) == {
        "table2.ground_truth.3d-neighborhood.mean_acc": 0.93, "table2.compact.lower.mean_acc": 0.8,
        "panoptic.oracle.pq_things": 0.7}
    for profile in ("full", "variance"):  # the committed figures: their one file is their stages' files gathered
        committed = pipeline.ROOT / "figures" / profile
        gathered = {k: v for f in sorted((committed / "metrics").glob("*.json")) for k, v in json.loads(f.read_text()).items()}
        assert json.loads((committed / "metrics.json").read_text()) == gathered


@pytest.mark.parametrize("name", ["04_label_transfer", "10_panoptic"])
def test_notebook_defaults_in_plain_jupyter_are_the_active_profiles(name, monkeypatch):
    """Opened in Jupyter with the kernel in notebooks/ and nothing injected, a notebook's
    parameters are the active profile's and its relative paths resolve from the repo root."""
    import papermill as pm
    from nbclient import NotebookClient

    monkeypatch.setenv("SEMMATCH_PROFILE", "smoke")
    path = ROOT / "notebooks" / f"{name}.ipynb"
    params = pipeline.notebook_parameters(name, "smoke")
    expected = {k: params[k] for k in pm.inspect_notebook(str(path)) if k in params}
    nb = nbformat.read(path, as_version=4)
    k = next(i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", []))
    cells = nb.cells[: k + 2]  # the parameters cell and the set-up cell after it
    names = sorted(expected)
    check = nbformat.v4.new_code_cell(
        f"import json, os\nprint(json.dumps({{'cwd': os.getcwd(), **{{k: globals()[k] for k in {names!r}}}}}))")
    nb.cells = [c for c in cells if c.cell_type == "code"] + [check]
    NotebookClient(nb, kernel_name="python3", resources={"metadata": {"path": str(ROOT / "notebooks")}}).execute()
    got = json.loads(nb.cells[-1].outputs[-1]["text"])
    assert Path(got.pop("cwd")) == ROOT
    assert got == expected and got["data_root"] == "data/smoke"


def test_progress_is_plain_text_under_the_pipeline(monkeypatch):
    from tqdm.std import tqdm as text_tqdm

    from semmatch.runtime.progress import text_mode, tqdm

    monkeypatch.setenv("SEMMATCH_PROGRESS", "text")
    assert text_mode()
    bar = tqdm(range(3), disable=True)
    assert type(bar) is text_tqdm
    monkeypatch.delenv("SEMMATCH_PROGRESS")
    assert not text_mode()


def test_flip_choice_merges_into_the_recipe(tmp_path, monkeypatch):
    """A choice made for some networks (e.g. extra training seeds) keeps the others' choices."""
    import pandas as pd

    import semmatch.segment as seg
    import semmatch.segment.viewpoint as vp
    from semmatch.experiments import height

    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "recipe.json").write_text(json.dumps({"flip": {"strong": True}}))
    (tmp_path / "models" / "compact@1.pt").write_bytes(b"")
    monkeypatch.setattr(height, "sweep_sequences", lambda root, split: {0.2: []})
    monkeypatch.setattr(seg, "load_model", lambda path, flip: flip)
    steps = []

    def scores(models, sweeps, frame_step, progress):
        steps.append(frame_step)
        return pd.DataFrame([{"model": name, "height": 0.2, "n_frames": 1, "miou": 0.5 if flip else 0.6,
                              "mean_acc": 0.9} for name, flip in models.items()])

    monkeypatch.setattr(vp, "viewpoint_gap_sequences", scores)
    choice, _ = height.choose_test_time_flip(tmp_path, ["compact@1"], frame_step=2, progress=False)
    assert steps == [2]  # the budget's frame step reaches the sweeps
    assert choice == {"compact@1": False}
    assert json.loads((tmp_path / "models" / "recipe.json").read_text())["flip"] == {"strong": True, "compact@1": False}


def test_stage_modules_follow_imports_everywhere(tmp_path):
    import json

    from semmatch.experiments.stagedeps import stage_modules

    pkg = tmp_path / "semmatch"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "runner.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from .b import g  # inside a function: still a dependency\n")
    (pkg / "b.py").write_text("from semmatch.sub import lazy_name\n")
    (pkg / "sub" / "__init__.py").write_text("_EXPORTS = {'lazy_name': 'impl'}\n")
    (pkg / "sub" / "impl.py").write_text("import numpy\n")
    (pkg / "unused.py").write_text("")
    (tmp_path / "notebooks").mkdir()
    cell = {"cell_type": "code", "metadata": {}, "outputs": [], "execution_count": None,
            "source": ["%matplotlib inline\n", "from semmatch import a\n"]}
    (tmp_path / "notebooks" / "nb.ipynb").write_text(json.dumps({"cells": [cell], "metadata": {}, "nbformat": 4,
                                                                  "nbformat_minor": 5}))
    mods = stage_modules("nb", root=tmp_path, runner="semmatch.runner")
    assert mods == ["semmatch/__init__.py", "semmatch/a.py", "semmatch/b.py", "semmatch/runner.py",
                    "semmatch/sub/__init__.py", "semmatch/sub/impl.py"]
    with pytest.raises(FileNotFoundError, match="no such notebook"):
        stage_modules("missing", root=tmp_path)


def test_stages_depend_on_what_they_use_and_not_on_the_rest():
    import yaml

    stages = yaml.safe_load((pipeline.ROOT / "dvc.yaml").read_text())["stages"]
    assert "semmatch/evaluate/metrics.py" in stages["evaluate_synthetic"]["deps"]
    assert "semmatch/evaluate/metrics.py" not in stages["simulate"]["deps"]  # editing the measures keeps the data
    for st in stages.values():
        assert "semmatch/experiments/pipeline.py" in st["deps"] and "semmatch" not in st["deps"]


def test_editing_views_or_execution_settings_reruns_no_stage():
    """DVC reruns a stage when a dependency or a tracked param changes: plots/views.py (views shown in the
    reports only), the README and snapshot writers, the confirm/ship subcommands and jobs/scheduler
    (how, not what) are neither for any stage; the stage command's entry point is; the figure code
    is a dependency exactly of the stages that write figure files."""
    import yaml

    untracked = ("semmatch/plots/views.py", "semmatch/experiments/readme.py",
                 "semmatch/experiments/snapshot.py", "semmatch/experiments/confirm.py")
    stages = yaml.safe_load((pipeline.ROOT / "dvc.yaml").read_text())["stages"]
    for name, st in stages.items():
        assert not [d for d in st["deps"] if d.startswith(untracked)], name
        assert "semmatch/experiments/__main__.py" in st["deps"], name  # `python -m semmatch.experiments run`
        keys = [k for p in st["params"] for k in ([p] if isinstance(p, str) else [k for ks in p.values() for k in ks])]
        assert not [k for k in keys if k.split(".")[-1] in ("jobs", "scheduler")], name
        draws = any(str(next(iter(o)) if isinstance(o, dict) else o).endswith(".png") for o in st["outs"])
        assert ("semmatch/plots/charts.py" in st["deps"]) == draws, name
    # 03 shows a 3D view (plots.views): its computing code stays tracked, the view module does not
    assert "semmatch/experiments/synthetic.py" in stages["reconstruct_upper"]["deps"]


def test_stage_modules_leave_out_display_only_modules(tmp_path):
    import json

    from semmatch.experiments.stagedeps import stage_modules

    pkg = tmp_path / "semmatch"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "runner.py").write_text("")
    (pkg / "compute.py").write_text("def show():\n    from .plots.views import view\n")
    (pkg / "plots").mkdir()
    (pkg / "plots" / "__init__.py").write_text("")
    (pkg / "plots" / "views.py").write_text("from ..only_for_views import colours\n")
    (pkg / "only_for_views.py").write_text("")
    (tmp_path / "notebooks").mkdir()
    cell = {"cell_type": "code", "metadata": {}, "outputs": [], "execution_count": None,
            "source": ["from semmatch import compute\n", "from semmatch.plots.views import view\n"]}
    (tmp_path / "notebooks" / "nb.ipynb").write_text(json.dumps({"cells": [cell], "metadata": {}, "nbformat": 4,
                                                                  "nbformat_minor": 5}))
    mods = stage_modules("nb", root=tmp_path, runner="semmatch.runner", leave_out=("semmatch.plots.views",))
    # the view's package runs when the view is imported: it stays a dependency, the view does not
    assert mods == ["semmatch/__init__.py", "semmatch/compute.py", "semmatch/plots/__init__.py",
                    "semmatch/runner.py"]
    every = stage_modules("nb", root=tmp_path, runner="semmatch.runner", leave_out=())
    assert {"semmatch/plots/views.py", "semmatch/only_for_views.py"} <= set(every)


def test_top_level_overrides_reach_the_profile(tmp_path):
    body = ("profiles:\n  p:\n    common: {seed: 0, voxel_size: 0.05, methods: [a, b]}\n"
            "    simulate: {n_frames_lower: 8}\n")
    f = tmp_path / "params.yaml"
    f.write_text("profile: p\nvoxel_size: null\nmethods: [b]\nn_frames_lower: 3\n" + body)
    p = pipeline.load_params(f)
    assert p["common"] == {"seed": 0, "voxel_size": 0.05, "methods": ["b"]}
    assert p["simulate"] == {"n_frames_lower": 3}
    assert pipeline.notebook_parameters("01_simulate", params_file=f)["n_frames_lower"] == 3
    f.write_text("profile: p\nvoxel_sise: 0.1\n" + body)
    with pytest.raises(ValueError, match="unknown top-level key.*voxel_sise"):
        pipeline.load_params(f)
    f.write_text("profile: p\nimage_width: 64\n" + body)
    with pytest.raises(ValueError, match="image_width=64 must match exactly one section"):
        pipeline.load_params(f)


def test_every_override_key_is_in_params_and_reaches_a_stage(tmp_path):
    import yaml

    top = yaml.safe_load((pipeline.ROOT / "params.yaml").read_text())
    stages = yaml.safe_load((pipeline.ROOT / "dvc.yaml").read_text())["stages"]
    declared = {p for st in stages.values() for p in st["params"] if isinstance(p, str)}
    for key in pipeline.OVERRIDABLE:
        assert key in top and top[key] is None, key  # committed params.yaml: the profiles decide
        assert key in declared, f"no stage reruns when {key} is overridden"
    assert "profiles" not in top  # in profiles.yaml: DVC shows all of params.yaml (test_dvc_shows_the_active_profile_only)
    for name in pipeline.read_params()["profiles"]:
        pipeline.load_params(pipeline.ROOT / "params.yaml", name)  # every override key resolves
    # every key can be set (networks is in common and in the panoptic section: common wins)
    text = (pipeline.ROOT / "params.yaml").read_text()
    (tmp_path / pipeline.PROFILES_FILE).write_text((pipeline.ROOT / pipeline.PROFILES_FILE).read_text())
    for key in pipeline.OVERRIDABLE:
        f = tmp_path / f"{key}.yaml"
        f.write_text(re.sub(rf"(?m)^{key}: null", f"{key}: [compact]" if key != "fused_base" else f"{key}: dbscan",
                            text))
        p = pipeline.load_params(f, "full")
        assert any(p[sec].get(key) in (["compact"], "dbscan") for sec in p if isinstance(p[sec], dict)), key
    assert pipeline.load_params(tmp_path / "networks.yaml", "full")["panoptic"]["networks"] == ["compact"]


def test_snapshot_shrinks_figures_and_drops_interactive_outputs(tmp_path):
    import base64
    import io

    import numpy as np
    from PIL import Image

    from semmatch.experiments.snapshot import snapshot_notebook, snapshot_reports

    rng = np.random.default_rng(0)
    img = (np.linspace(0, 255, 2000)[None, :, None] * np.ones((800, 1, 3)) + rng.normal(0, 8, (800, 2000, 3)))
    buf = io.BytesIO()
    Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(buf, "PNG")
    png = base64.b64encode(buf.getvalue()).decode()
    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell("plot()")
    cell.outputs = [
        nbformat.v4.new_output("display_data", data={"image/png": png, "text/plain": "<Figure>"}),
        nbformat.v4.new_output("display_data", data={"application/vnd.plotly.v1+json": {"data": []}}),
        nbformat.v4.new_output("stream", name="stdout", text="table\n"),
    ]
    nb.cells = [nbformat.v4.new_markdown_cell("# narrative"), cell]
    src = tmp_path / "rep" / "05_x.ipynb"
    src.parent.mkdir()
    nbformat.write(nb, src)
    [dst] = snapshot_reports(tmp_path / "rep", tmp_path / "snap", profile="smoke", max_width=400)
    assert dst.stat().st_size < src.stat().st_size / 5
    out = nbformat.read(dst, as_version=4)
    fig, plotly, stream = out.cells[1].outputs
    assert "image/png" not in fig["data"] and "text/plain" in fig["data"]
    small = Image.open(io.BytesIO(base64.b64decode(fig["data"]["image/jpeg"])))
    assert small.size == (400, 160)
    assert "semmatch show" in plotly["data"]["text/markdown"] and stream["text"] == "table\n"
    assert out.metadata["semmatch_snapshot"]["profile"] == "smoke"
    with pytest.raises(FileNotFoundError, match="no executed notebooks"):
        snapshot_reports(tmp_path / "empty", tmp_path / "snap2", profile="smoke")
    (tmp_path / "bad.ipynb").write_text("{not json")
    with pytest.raises(ValueError, match="bad.ipynb: not a readable notebook"):
        snapshot_notebook(tmp_path / "bad.ipynb", tmp_path / "o.ipynb")


def test_snapshots_leave_out_machine_notices_and_machine_paths(tmp_path):
    from semmatch.experiments.snapshot import snapshot_notebook

    text = ("/home/u/.venv/lib/python3.11/site-packages/numba/np/ufunc/parallel.py:373: NumbaWarning: "
            "\x1b[1mThe TBB threading layer requires TBB version 2021 update 6 or later\x1b[0m\n"
            "  warnings.warn(problem)\n"
            "/work/clone/semmatch/experiments/real_poses.py:200: UserWarning: /work/clone/data/full/scenes/eval/"
            "bedroom_7001/lower_noisy: RGB-D odometry found no solution for 1 frame(s)\n"
            "  est = estimate_poses(seq)\n"
            "transfer: 100%\n")
    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell("run()")
    cell.outputs = [nbformat.v4.new_output("stream", name="stderr", text=text),
                    nbformat.v4.new_output("stream", name="stderr", text=text.split("  warnings.warn(problem)\n")[0]
                                           + "  warnings.warn(problem)\n")]
    nb.cells = [cell]
    nb.metadata["papermill"] = {"input_path": "/work/clone/notebooks/04_x.ipynb", "parameters": {"seed": 1}}
    nbformat.write(nb, tmp_path / "04_x.ipynb")
    out = nbformat.read(snapshot_notebook(tmp_path / "04_x.ipynb", tmp_path / "s.ipynb"), as_version=4)
    [stream] = out.cells[0].outputs  # the second held only the notice: gone
    assert stream["text"] == ("semmatch/experiments/real_poses.py:200: UserWarning: data/full/scenes/eval/bedroom_7001/"
                              "lower_noisy: RGB-D odometry found no solution for 1 frame(s)\n"
                              "  est = estimate_poses(seq)\ntransfer: 100%\n")
    assert out.metadata["papermill"] == {"input_path": "notebooks/04_x.ipynb", "parameters": {"seed": 1}}


def test_snapshots_show_injected_parameters_and_printed_values_from_the_repository(tmp_path):
    from semmatch.experiments.snapshot import snapshot_notebook

    nb = nbformat.v4.new_notebook()
    params = nbformat.v4.new_code_cell('data_root = "/tmp/pytest-of-u/pytest-1/smoke0/data"\nseed = 1')
    params.metadata["tags"] = ["injected-parameters"]
    shown = nbformat.v4.new_code_cell("cfg")
    shown.outputs = [nbformat.v4.new_output("execute_result", execution_count=1, data={
        "text/plain": "TrainConfig(out='/tmp/pytest-of-u/pytest-1/smoke0/data/models/compact.pt')"})]
    nb.cells = [params, shown]
    nbformat.write(nb, tmp_path / "02_x.ipynb")
    out = nbformat.read(snapshot_notebook(tmp_path / "02_x.ipynb", tmp_path / "s.ipynb"), as_version=4)
    assert out.cells[0].source == 'data_root = "data"\nseed = 1'
    assert out.cells[1].outputs[0]["data"]["text/plain"] == "TrainConfig(out='data/models/compact.pt')"


def test_committed_snapshots_hold_no_machine_path_or_machine_notice():
    for p in sorted((ROOT / "reports" / "snapshot").rglob("*.ipynb")):
        text = p.read_text()
        assert "NumbaWarning" not in text, p
        assert not re.search(r"[\"'(]/(?:tmp|root|home|work)/", text), p


def test_a_notebook_run_with_another_parameter_file_reads_that_file(tmp_path):
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    params = nbformat.v4.new_code_cell("profile = None\nseed = None")
    params.metadata["tags"] = ["parameters"]
    setup = nbformat.v4.new_code_cell("from semmatch.experiments import notebook_setup\n"
                                      "globals().update(notebook_setup('01_simulate', globals()))\n"
                                      "assert seed == 41, seed")
    nb.cells = [params, setup]
    (tmp_path / "nb").mkdir()
    nbformat.write(nb, tmp_path / "nb" / "01_simulate.ipynb")
    # a profile that only this file has (the repository's params.yaml does not know it)
    (tmp_path / "params.yaml").write_text("profile: mine\nprofiles:\n  mine:\n    common: {seed: 41}\n    simulate: {}\n")
    pipeline.run_notebook("01_simulate", "mine", notebooks_dir=tmp_path / "nb", params_file=tmp_path / "params.yaml",
                          reports_dir=tmp_path / "rep", cwd=tmp_path)


def test_layout_scene_dir_by_index(tmp_path):
    from semmatch.experiments.layout import Layout

    for sid in ("office_7002", "bedroom_7001"):
        (tmp_path / "scenes" / "eval" / sid).mkdir(parents=True)
        (tmp_path / "scenes" / "eval" / sid / "scene.ply").write_text("ply")
    layout = Layout(tmp_path)
    assert layout.scene_dir(0).name == "bedroom_7001" and layout.scene_dir(1).name == "office_7002"
    with pytest.raises(ValueError, match="scene index 2 out of range: 2 eval scenes"):
        layout.scene_dir(2)


def _scene_rows(root: str, tag: str, sid: str) -> list[dict]:
    return [{"root": root, "tag": tag, "scene": sid, "k": k} for k in range(2)]


def test_layout_map_scenes_runs_one_task_per_scene_in_order(tmp_path):
    from semmatch.experiments.layout import Layout

    for split, sid in (("eval", "office_7002"), ("eval", "bedroom_7001"), ("val", "office_501")):
        (tmp_path / "scenes" / split / sid).mkdir(parents=True)
        (tmp_path / "scenes" / split / sid / "scene.ply").write_text("ply")
    layout = Layout(tmp_path)
    rows = layout.map_scenes(_scene_rows, "t", progress=False)
    root = str(tmp_path.resolve())
    assert rows == [{"root": root, "tag": "t", "scene": sid, "k": k} for sid in ("bedroom_7001", "office_7002")
                    for k in range(2)]
    per_scene = layout.map_scenes(_scene_rows, "t", split="val", flatten=False, progress=False)
    assert per_scene == [_scene_rows(root, "t", "office_501")]
    # scene ids or folders, in the order given
    chosen = layout.map_scenes(_scene_rows, "u", scenes=[layout.scene_dir(1), "bedroom_7001"], progress=False)
    assert [r["scene"] for r in chosen] == ["office_7002"] * 2 + ["bedroom_7001"] * 2


def test_root_is_found_from_the_working_directory_not_the_package(tmp_path, monkeypatch):
    """A checkout is found by walking up to params.yaml (Jupyter starts in notebooks/), or named
    by SEMMATCH_ROOT; the package's own location does not decide (a shared or non-editable install)."""
    other = tmp_path / "checkout"
    (other / "notebooks" / "deep").mkdir(parents=True)
    (other / "params.yaml").write_text("profile: smoke\n")
    monkeypatch.delenv(pipeline.ROOT_ENV, raising=False)
    assert pipeline.find_root(other / "notebooks" / "deep") == other.resolve()
    monkeypatch.chdir(other / "notebooks")
    assert pipeline.find_root() == other.resolve()
    monkeypatch.setenv(pipeline.ROOT_ENV, str(other))
    assert pipeline.find_root(pipeline.ROOT) == other.resolve()  # the variable wins over the search
    monkeypatch.setenv(pipeline.ROOT_ENV, str(tmp_path))
    with pytest.raises(FileNotFoundError, match="SEMMATCH_ROOT=.*no params.yaml"):
        pipeline.find_root()
