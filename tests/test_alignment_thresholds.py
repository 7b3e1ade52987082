"""The rule that chooses ``semmatch align``'s refusal thresholds on validation pairs
(semmatch.experiments.alignment_thresholds), on hand-made pairs whose answer is known."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from semmatch.experiments.alignment_study import main as study_main
from semmatch.experiments.alignment_study import validation_seed_check
from semmatch.experiments.alignment_thresholds import choose_thresholds, judge_rows, must_refuse
from semmatch.poses.alignment import DEFAULT_CHECKS


def pair(scene, person, sf, err_cm=1.0, rot=0.2, rmse=0.022, agreement=1.0, angle=0.5, offset=0.01):
    return dict(scene=scene, person=person, structure_fitness=sf, agreement=agreement, inlier_rmse=rmse,
                floor_angle_deg=angle, floor_offset_m=offset,
                trans_err_mesh_m=err_cm / 100 if person == scene else np.nan,
                rot_err_mesh_deg=rot if person == scene else np.nan)


def rows(*pairs):
    return pd.DataFrame(list(pairs))


def test_labels_wrong_pairs_and_right_pairs_off_target():
    r = rows(pair("a", "a", 0.5), pair("b", "b", 0.5, err_cm=6.0), pair("c", "c", 0.5, rot=2.5), pair("a", "b", 0.2))
    assert must_refuse(r).tolist() == [False, True, True, True]
    with pytest.raises(ValueError, match="without a mesh error"):
        must_refuse(rows(pair("a", "a", 0.5, err_cm=np.nan)))
    # pairs stored without a mesh fit: labelled by the trajectory truth when asked
    t = r.rename(columns={"trans_err_mesh_m": "trans_err_m", "rot_err_mesh_deg": "rot_err_deg"})
    assert must_refuse(t, truth="trajectory").tolist() == [False, True, True, True]
    with pytest.raises(ValueError, match="without a mesh error"):
        must_refuse(t)
    # the mesh fit where a pair has one, the trajectory truth elsewhere
    mixed = pd.concat([r.iloc[:1].assign(trans_err_m=0.09, rot_err_deg=0.1), t.iloc[1:]], ignore_index=True)
    assert must_refuse(mixed, truth="mesh-or-trajectory").tolist() == [False, True, True, True]
    assert must_refuse(mixed, truth="trajectory").tolist() == [True, True, True, True]


def test_the_minimum_goes_to_the_middle_of_the_gap_between_wrong_and_right_pairs():
    r = rows(pair("a", "a", 0.40), pair("b", "b", 0.60), pair("c", "c", 0.50),
             pair("a", "b", 0.10), pair("b", "c", 0.32), pair("c", "a", 0.20))
    th, steps = choose_thresholds(r)
    assert th["min_structure_fitness"] == pytest.approx(0.36)  # (0.32 + 0.40) / 2
    assert judge_rows(r, th).tolist() == [True, True, True, False, False, False]
    # the other checks refuse nothing here and their defaults are kept (open runs that hold them)
    for k in ("min_agreement", "max_inlier_rmse", "max_floor_angle", "max_floor_offset"):
        assert th[k] == DEFAULT_CHECKS[k]
    assert steps[0]["check"] == "min_structure_fitness" and steps[0]["bad_accepted"] == 0


def test_a_right_pair_off_target_is_refused_by_the_check_that_can_and_a_wrong_acceptance_costs_most():
    # the off-target right pair (c) scores high structure fitness but a large floor angle: only the
    # floor-angle check can refuse it, at the price of no good pair
    r = rows(pair("a", "a", 0.40, angle=0.5), pair("b", "b", 0.60, angle=1.0), pair("c", "c", 0.70, err_cm=8, angle=2.8),
             pair("a", "b", 0.10), pair("b", "c", 0.20), pair("c", "a", 0.25))
    assert judge_rows(r, DEFAULT_CHECKS)[2]  # accepted under the defaults (3 degrees)
    th, _ = choose_thresholds(r)
    assert th["max_floor_angle"] == pytest.approx(1.9)  # (1.0 + 2.8) / 2
    assert judge_rows(r, th).tolist() == [True, True, False, False, False, False]
    # a wrong pair above a right one: refusing it refuses the right pair too, and that is the rule's choice
    r2 = rows(pair("a", "a", 0.40), pair("b", "b", 0.60), pair("a", "b", 0.45), pair("b", "a", 0.1))
    th2, _ = choose_thresholds(r2)
    assert th2["min_structure_fitness"] == pytest.approx(0.525)
    assert judge_rows(r2, th2).tolist() == [False, True, False, False]


def test_only_validation_scenes_choose(tmp_path):
    for name in ("office_0503", "office_7003"):
        (tmp_path / name).mkdir()
    validation_seed_check([tmp_path / "office_0503"])
    with pytest.raises(ValueError, match="not a validation seed"):
        validation_seed_check([tmp_path / "office_7003"])
    with pytest.raises(ValueError, match="not a validation seed"):
        study_main(["validate", str(tmp_path / "office_7003"), "--poses", str(tmp_path), "--out", str(tmp_path / "o")])
