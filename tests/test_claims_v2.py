"""The analysis plan v2's verdict rules, its re-judging of the v1 run, and the plan-before-run order in git."""

from __future__ import annotations

import dataclasses
import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from semmatch.experiments.analysis_plan import PLAN_FILE, PLAN_V2_FILE, load_analysis_plan, plan_for_seeds
from semmatch.experiments.claims import check_claims, claim_verdicts, judge_figures, judge_speed_claims
from semmatch.experiments.plan_order import PLAN_DOC, files_before_plan
from semmatch.experiments.rules_v2 import _judge_family_v2, claim_rule_v2, comparison_verdict_v2

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "figures" / "confirm" / "seeds-8001-8006"
V2 = load_analysis_plan(PLAN_V2_FILE)
#: the v2 plan with its first version's interval over networks (the two-level bootstrap)
V2_BOOT = dataclasses.replace(V2, raw={**V2.raw, "inference": {**V2.raw["inference"], "interval": "two-level-bootstrap"}})
KINDS = ("living_room", "bedroom", "office", "apartment")


def _family(rows: list[tuple[float, float, float, float]], **cluster) -> pd.DataFrame:
    """A synthetic comparison family: (diff, lo, hi, raw one-sided p of the wrong direction) per row."""
    fam = pd.DataFrame(rows, columns=["diff", "lo", "hi", "p_neg"])
    fam["p_pos"] = fam["p_eq"] = fam["p_beyond1"] = 0.5
    fam["cluster_lo"] = cluster.get("lo", fam["lo"])
    fam["cluster_hi"] = cluster.get("hi", fam["hi"])
    fam["cluster_p_neg"] = cluster.get("p_neg", fam["p_neg"])
    fam["cluster_p_beyond1"] = 0.5
    return fam


def test_plan_v2_carries_v1_claims_and_picks_its_seeds():
    v1 = load_analysis_plan(PLAN_FILE)
    assert V2.rules == "v2" and v1.rules == "v1" and V2.alpha == 0.025
    assert {c.id: c for c in V2.claims if c.id.startswith("C")} == {c.id: c for c in v1.claims}
    assert {"F1", "F1-real", "F2", "F2-real"} <= {c.id for c in V2.claims}
    assert plan_for_seeds(range(8101, 8107)).rules == "v2"
    assert plan_for_seeds(range(8001, 8007)).rules == "v1"
    with pytest.raises(ValueError, match="mix"):
        plan_for_seeds([8101, 8001])


def test_holds_below_sesoi_is_not_holds():
    # C2-like: +0.016 [0.012, 0.020] is above 0 but its lower bound is not beyond the SESOI
    assert comparison_verdict_v2("best", 0.012, 0.019, 1.0, sesoi=0.02, alpha=0.025) == "equivalent"
    assert comparison_verdict_v2("best", 0.012, 0.035, 1.0, sesoi=0.02, alpha=0.025) == "inconclusive"
    assert comparison_verdict_v2("best", 0.021, 0.035, 1.0, sesoi=0.02, alpha=0.025) == "holds"
    fam = _judge_family_v2(_family([(0.016, 0.012, 0.030, 0.99), (0.05, 0.03, 0.07, 0.99)]), "best", 0.02, 0.025)
    assert list(fam["verdict"]) == ["inconclusive", "holds"]
    assert list(fam["min_effect"]) == [False, True] and list(fam["beyond_zero"]) == [True, True]
    assert claim_rule_v2(fam["verdict"], "best") == "inconclusive"


def test_intersection_union_needs_no_holm():
    # C13-noise-like: four comparisons each beyond the SESOI with raw p ~ 0.02; Holm over 4 would
    # make them 0.08 (v1: inconclusive); the intersection-union test takes them as they are
    fam = _judge_family_v2(_family([(0.08, 0.021, 0.14, 0.999)] * 4), "best", 0.02, 0.025)
    assert list(fam["verdict"]) == ["holds"] * 4
    assert claim_rule_v2(fam["verdict"], "best") == "holds"
    # one comparison short of the SESOI leaves the claim inconclusive
    fam = _judge_family_v2(_family([(0.08, 0.021, 0.14, 0.999)] * 3 + [(0.05, 0.019, 0.08, 0.999)]), "best",
                           0.02, 0.025)
    assert claim_rule_v2(fam["verdict"], "best") == "inconclusive"


def test_wrong_direction_refutes_with_holm():
    # C15-like: 4 of 10 comparisons significantly against the claim
    rows = [(-0.06, -0.09, -0.03, 1e-4)] * 4 + [(0.0, -0.03, 0.03, 0.5)] * 6
    fam = _judge_family_v2(_family(rows), "beats", 0.02, 0.025)
    assert (fam["verdict"] == "against").sum() == 4
    assert claim_rule_v2(fam["verdict"], "beats") == "refuted"
    # Holm in the wrong direction: a raw 0.02 among 10 comparisons is not enough to refute
    rows = [(-0.03, -0.06, -0.001, 0.02)] + [(0.0, -0.03, 0.03, 0.5)] * 9
    fam = _judge_family_v2(_family(rows), "beats", 0.02, 0.025)
    assert claim_rule_v2(fam["verdict"], "beats") == "inconclusive"
    # a similar claim is refuted by a comparison shown beyond the margin
    assert comparison_verdict_v2("similar", 0.03, 0.05, 0.001, sesoi=0.02, alpha=0.025) == "against"
    assert comparison_verdict_v2("similar", -0.01, 0.015, 0.9, sesoi=0.02, alpha=0.025) == "holds"


def test_cluster_sensitivity_is_reported_not_deciding():
    # the scene-level interval holds; the kind-cluster one (3 df) does not: the claim still holds
    fam = _judge_family_v2(_family([(0.05, 0.03, 0.07, 0.999)], lo=np.array([-0.01]), hi=np.array([0.11])),
                           "beats", 0.02, 0.025)
    fam = fam.assign(claim="X", reference="fusion", statement="s", data="synthetic", role="primary", kind="beats",
                     paper_in_ci=None, interval_method="t over scenes (one network); provisional")
    row = claim_verdicts(fam).iloc[0]
    assert row["verdict"] == "holds" and row["verdict_cluster"] == "inconclusive"
    assert row["min_effect"].startswith("1 of 1 beyond SESOI")


def test_check_claims_v2_on_synthetic_scenes():
    # 3 scenes per kind; method a beats b by 0.05 with small noise; kind offsets
    rng = np.random.default_rng(0)
    rows = []
    for k, kind in enumerate(KINDS):
        for s in range(3):
            scene = f"{kind}_{9000 + s}"
            base = 0.7 + 0.02 * k + rng.normal(0, 0.01)
            for method, v in (("lower", base), ("3d-neighborhood", base + 0.05 + rng.normal(0, 0.005)),
                              ("fused", base + 0.01 + rng.normal(0, 0.005))):
                rows.append(dict(scene=scene, model="compact", method=method, mean_acc=v))
    df = pd.DataFrame(rows)
    claims = [c for c in V2.claims if c.id in ("C1", "F1")]
    out = check_claims(df, methods=["3d-neighborhood"], plan=V2, claims=claims)
    by = out.set_index("claim")
    assert by.loc["C1", "verdict"] == "holds" and bool(by.loc["C1", "min_effect"])
    assert by.loc["F1", "verdict"] in ("equivalent", "inconclusive") and not by.loc["F1", "min_effect"]
    assert {"cluster_lo", "cluster_hi", "verdict_cluster", "interval_method"} <= set(out.columns)
    assert out["interval_method"].eq("t over scenes (one network); provisional").all()
    # the same rows transferred from the ground-truth map depend on no network: never provisional
    gt = [c for c in V2.claims if c.id == "C6-gt"]
    gt_rows = df.assign(model="ground truth", method=df["method"].map({"lower": "3d-slic", "3d-neighborhood":
                                                                        "3d-projected-sp", "fused": "dbscan"}))
    out = check_claims(gt_rows, methods=["3d-slic", "3d-projected-sp", "dbscan"], plan=V2, claims=gt)
    assert len(out) and out["interval_method"].eq("t over scenes (one network)").all()


def test_several_networks_use_the_two_component_t():
    """The plan's interval over networks and scenes: the two-component t (no resampling): holds on a clear
    gain, refuted when the networks are worse than lower, the method named in the table."""
    rows = [dict(scene=f"{kind}_{9000 + s}", model="compact", method=m, training_seed=n,
                 mean_acc=0.7 + (0.06 if m == "3d-neighborhood" else 0.0) + 0.01 * n + 0.003 * s * (m == "lower"))
            for kind in KINDS for s in range(3) for n in range(3) for m in ("lower", "3d-neighborhood")]
    df = pd.DataFrame(rows)
    claims = [c for c in V2.claims if c.id == "C1"]
    out = check_claims(df, methods=["3d-neighborhood"], plan=V2, claims=claims)
    assert out["interval_method"].iloc[0] == "two-component t (3 networks)"
    assert out["verdict"].iloc[0] == "holds" and out["lo"].iloc[0] > 0.02
    flipped = df.assign(mean_acc=np.where(df["method"] == "lower", df["mean_acc"] + 0.12, df["mean_acc"]))
    out = check_claims(flipped, methods=["3d-neighborhood"], plan=V2, claims=claims)
    assert out["verdict"].iloc[0] == "against" and out["p_against"].iloc[0] < 0.001


def test_several_networks_need_the_two_level_bootstrap(monkeypatch):
    from semmatch.evaluate import stats

    rows = [dict(scene=f"{kind}_{9000 + s}", model="compact", method=m, training_seed=n,
                 mean_acc=0.7 + (0.06 if m == "3d-neighborhood" else 0.0) + 0.01 * n + 0.001 * s)
            for kind in KINDS for s in range(3) for n in range(3) for m in ("lower", "3d-neighborhood")]
    df = pd.DataFrame(rows)
    claims = [c for c in V2.claims if c.id == "C1"]
    if not hasattr(stats, "two_level_bootstrap"):
        with pytest.raises(ValueError, match="two_level_bootstrap"):
            check_claims(df, methods=["3d-neighborhood"], plan=V2_BOOT, claims=claims)

    def fake(values, networks, scenes, strata, *, confidence, n_resamples, seed):
        # the contract: two-sided bounds lo/hi and one-sided lower/upper at `confidence`, a fixed
        # draw for a fixed seed (here a normal around the mean, sd 0.005)
        assert len(values) == len(networks) == len(scenes) == len(strata) == 36 and n_resamples == 10000
        means = np.random.default_rng(seed).normal(np.mean(values), 0.005, n_resamples)
        a = 1.0 - confidence
        lo, hi, lower, upper = np.quantile(means, [a / 2, 1 - a / 2, a, 1 - a])
        return SimpleNamespace(mean=float(np.mean(values)), lo=lo, hi=hi, lower=lower, upper=upper)

    monkeypatch.setattr(stats, "two_level_bootstrap", fake, raising=False)
    out = check_claims(df, methods=["3d-neighborhood"], plan=V2_BOOT, claims=claims)
    assert out["interval_method"].iloc[0] == "two-level bootstrap (3 networks)"
    assert out["verdict"].iloc[0] == "holds" and out["lo"].iloc[0] > 0.02
    assert out["p_against"].iloc[0] == 1.0  # no resample below 0: the bound never excludes it
    # the same networks, now worse than lower: refuted through the bound-derived p-value and Holm
    flipped = df.assign(mean_acc=np.where(df["method"] == "lower", df["mean_acc"] + 0.12, df["mean_acc"]))
    out = check_claims(flipped, methods=["3d-neighborhood"], plan=V2_BOOT, claims=claims)
    assert out["verdict"].iloc[0] == "against" and out["p_against"].iloc[0] < 0.001


def _fake_bootstrap(values, networks, scenes, strata, *, confidence, n_resamples, seed):
    """A stand-in for ``two_level_bootstrap``: a narrow interval around the mean."""
    a = 1.0 - confidence
    m = float(np.mean(values))
    return SimpleNamespace(mean=m, lo=m - 0.01 * (1 - a), hi=m + 0.01 * (1 - a), lower=m - 0.01, upper=m + 0.01)


def test_judge_figures_v2_on_several_networks(tmp_path, monkeypatch):
    from semmatch.evaluate import stats

    monkeypatch.setattr(stats, "two_level_bootstrap", _fake_bootstrap, raising=False)
    rows = [dict(scene=f"{kind}_{9000 + s}", route="own", reference="fusion", model="compact", method=m,
                 training_seed=n, mean_acc=0.7 + 0.05 * (m == "fused") + 0.001 * (s + n), color_acc=0.8,
                 jaccard=0.6, sorensen=0.7)
            for kind in KINDS for s in range(3) for n in range(3) for m in ("lower", "upper", "3d-neighborhood", "fused")]
    pd.DataFrame(rows).to_csv(tmp_path / "table2_per_scene.csv", index=False)
    pd.DataFrame({"scene": sorted({r["scene"] for r in rows}), "route": "own",
                  "support": np.linspace(0.5, 0.9, 12)}).to_csv(tmp_path / "support_per_scene.csv", index=False)
    table = judge_figures(tmp_path, plan=V2_BOOT).set_index("claim")
    assert table.loc["F1", "verdict"] == "holds" and "two-level bootstrap (3 networks)" in table.loc["F1", "interval"]
    assert (tmp_path / "secondary_s1_support.csv").is_file()


def test_speed_v2_reads_bench_medians():
    table = pd.DataFrame({"method": ["2d-slic", "3d-slic", "dbscan", "3d-neighborhood"],
                          "median": [37.0, 40.0, 41.0, 300.0], "min": [29.5, 35.0, 36.0, 280.0]})
    v = judge_speed_claims(table, plan=V2).set_index("claim")["verdict"]
    assert v["P1"] == "holds" and v["P3"] == "does not hold"  # 2d-slic's lowest run is below 30
    assert judge_speed_claims(table.assign(min=31.0), plan=V2).set_index("claim")["verdict"]["P3"] == "holds"
    one = pd.DataFrame({"method": ["2d-slic"], "cpu_fps": [50.0]})  # Table 1: descriptive under v2
    assert set(judge_speed_claims(one, plan=V2)["verdict"]) == {"not judged"}


@pytest.mark.slow
@pytest.mark.skipif(not (RUN / "table2_per_scene.csv").is_file(), reason="the v1 confirmatory run is not here")
def test_v1_verdicts_regenerate_identically(tmp_path):
    judge_figures(RUN, tmp_path, plan=load_analysis_plan(PLAN_FILE))
    for name in ("claims_all.csv", "verdicts.csv", "verdicts.md", "findings_all.md"):
        assert (tmp_path / name).read_bytes() == (RUN / name).read_bytes(), name


@pytest.mark.slow
@pytest.mark.skipif(not (RUN / "table2_per_scene.csv").is_file(), reason="the v1 confirmatory run is not here")
def test_rejudged_table_regenerates():
    from semmatch.experiments.rejudge import rejudge_markdown

    doc = ROOT / "docs" / "results_confirmatory_v1_under_v2.md"
    command = ("python -m semmatch.experiments rejudge --rules v2 --figures figures/confirm/seeds-8001-8006 "
               "--out docs/results_confirmatory_v1_under_v2.md")
    assert rejudge_markdown("figures/confirm/seeds-8001-8006", rules="v2", command=command) == doc.read_text()


def _git(cwd: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout


def test_plan_v2_precedes_every_file_of_its_seeds():
    try:
        shallow = _git(ROOT, "rev-parse", "--is-shallow-repository").strip() == "true"
        first = _git(ROOT, "log", "--format=%H", "--diff-filter=A", "--", PLAN_DOC).split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("no git history here")
    if shallow or not first:
        pytest.skip("git history is shallow or does not hold the v2 plan's commit")
    assert files_before_plan(ROOT) == []


def test_plan_order_check_fails_on_a_seed_file_before_the_plan(tmp_path):
    try:
        _git(tmp_path, "init", "-q")
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("git is not available")
    _git(tmp_path, "config", "user.email", "t@t")
    _git(tmp_path, "config", "user.name", "t")
    early = tmp_path / "figures" / "confirm" / "seeds-8101-8106" / "table2_per_scene.csv"
    early.parent.mkdir(parents=True)
    early.write_text("x\n")
    _git(tmp_path, "add", "-A")
    _git(tmp_path, "commit", "-qm", "a scene file first")
    plan = tmp_path / PLAN_DOC
    plan.parent.mkdir(parents=True)
    plan.write_text("plan\n")
    (tmp_path / "data_living_room_8102.txt").write_text("after\n")
    _git(tmp_path, "add", "-A")
    _git(tmp_path, "commit", "-qm", "the plan, then a later file")
    bad = files_before_plan(tmp_path)
    assert [p for _, p in bad] == ["figures/confirm/seeds-8101-8106/table2_per_scene.csv"]


def test_a_confirm_runs_tables_get_their_training_seeds_and_its_speed_claims_the_bench(tmp_path, monkeypatch):
    """The wiring of a v2 run: per-scene tables as notebooks 05-07 write them with several training
    seeds (``compact@1`` ...) get ``training_seed`` (ground truth none), and P1-P3 read a small
    ``bench_speed.json`` (the plan's benchmark) instead of Table 1; the v1 plan ignores both."""
    import json

    from semmatch.evaluate import stats
    from semmatch.experiments.plan_networks import label_training_seeds, plan_networks, with_training_seed
    from semmatch.experiments.speed_claims import BENCH_RECORD

    monkeypatch.setattr(stats, "two_level_bootstrap", _fake_bootstrap, raising=False)
    rows = [dict(scene=f"{kind}_{9000 + s}", route="own", reference="fusion", model=net, method=m,
                 mean_acc=0.7 + 0.05 * (m == "fused") + 0.001 * s + (0.03 if m == "3d-slic" and net == "ground truth"
                                                                     else 0.0), color_acc=0.8, jaccard=0.6, sorensen=0.7)
            for kind in KINDS for s in range(3) for net in ("compact", "compact@1", "compact@2", "ground truth")
            for m in (("3d-slic", "3d-projected-sp") if net == "ground truth" else ("lower", "3d-slic", "fused"))]
    pd.DataFrame(rows).to_csv(tmp_path / "table2_per_scene.csv", index=False)
    pd.DataFrame({"method": ["2d-slic", "3d-slic"], "cpu_fps": [50.0, 5.0]}).to_csv(tmp_path / "table1_speed.csv",
                                                                                  index=False)
    assert label_training_seeds(tmp_path) == [tmp_path / "table2_per_scene.csv"]
    assert label_training_seeds(tmp_path) == []  # once
    table = pd.read_csv(tmp_path / "table2_per_scene.csv")
    assert list(table.columns[3:5]) == ["model", "training_seed"] and set(table["model"]) == {"compact", "ground truth"}
    assert table.groupby("model")["training_seed"].agg(lambda v: sorted(v.dropna().unique())).to_dict() == \
        {"compact": [0, 1, 2], "ground truth": []}
    assert "training_seed" in (tmp_path / "table2_per_scene.md").read_text()
    with pytest.raises(ValueError, match="needs a 'model' column"):
        with_training_seed(pd.DataFrame({"scene": ["a"]}))
    spread = {m: {"median": f, "min": f - 1, "max": f + 1} for m, f in
              (("2d-slic", 37.0), ("3d-slic", 40.0), ("fused", 45.0), ("3d-neighborhood (exact)", 5.0),
               ("reference (closest point)", 12.0))}
    runs = [{"2d-slic": 37.0, "load_average": 0.5}, {"2d-slic": 36.0, "load_average": 0.7}]
    (tmp_path / BENCH_RECORD).write_text(json.dumps({
        "maps": {"fused": {"spread": spread, "runs": runs}}, "command": "semmatch bench transfer --map fused --repeat 5",
        "machine": {"device_name": "Test CPU", "cpu_count": 2}}))
    verdicts = judge_figures(tmp_path, plan=V2_BOOT).set_index("claim")
    assert verdicts.loc["F1", "verdict"] == "holds" and "(3 networks)" in verdicts.loc["F1", "interval"]
    assert verdicts.loc["C6-gt", "interval"].startswith("t over scenes (one network)")  # no training seed
    assert verdicts.loc["P3", "verdict"] == "holds" and verdicts.loc["P3", "data"].startswith("speed (semmatch bench")
    evidence = pd.read_csv(tmp_path / "claims_speed_bench.csv").set_index("claim")["evidence"]
    assert "Test CPU (2 CPUs), load 0.5-0.7, reference 12.0 FPS" in evidence["P3"]  # the exact variant is no method
    v1 = judge_figures(tmp_path, tmp_path / "v1", plan=load_analysis_plan(PLAN_FILE)).set_index("claim")
    assert v1.loc["P3", "data"] == "speed (Table 1)" and v1.loc["P3", "verdict"] == "does not hold"
    assert plan_networks(["compact", "strong"], load_analysis_plan(PLAN_FILE), tmp_path) == ["compact", "strong"]


def test_a_v2_run_evaluates_every_shipped_training_seed(tmp_path, capsys):
    """With the ``seeds`` branch's :func:`~semmatch.segment.shipping.shipped_seeds` (skipped before it is merged)."""
    import json

    from semmatch.experiments.plan_networks import plan_networks
    from semmatch.segment import shipping

    if not hasattr(shipping, "shipped_seeds"):
        pytest.skip("semmatch.segment.shipping.shipped_seeds (the seeds branch) is not merged yet")
    for name, seed in (("compact", 0), ("compact@2", 2), ("strong", 0)):
        (tmp_path / f"{name}.pt").write_bytes(b"stand-in")
        (tmp_path / f"{name}.json").write_text(json.dumps({"train_config": {"seed": seed}}))
    assert plan_networks(["compact", "strong"], V2, tmp_path) == ["compact", "compact@2", "strong"]
    assert "compact: training seeds [1] of the plan are not shipped" in capsys.readouterr().err
