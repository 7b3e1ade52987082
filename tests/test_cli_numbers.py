"""Every numeric option of every verb (found by walking the parser) takes its value through
:func:`semmatch.cli.common.number`: NaN and infinities are refused, values outside the option's
range are refused, the help line states the range, and the errors come with the verb's usage."""

from __future__ import annotations

import argparse

import pytest

from semmatch.cli import build_parser, main
from semmatch.cli.common import walk_parsers


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return build_parser()


def _numeric(parser) -> list[tuple[str, argparse.Action]]:
    """Every option (hidden aliases too) whose value is a number: a numeric ``type`` or default."""
    found = []
    for name, p in walk_parsers(parser):
        for a in p._actions:
            if not a.option_strings or a.nargs == 0 or isinstance(a, argparse._HelpAction | argparse._VersionAction):
                continue
            default = a.default if not isinstance(a.default, list) else (a.default or [None])[0]
            if (a.type in (int, float) or hasattr(a.type, "range_text")
                    or (isinstance(default, int | float) and not isinstance(default, bool))):
                found.append((f"{name} {a.option_strings[0]}", a))
    return found


def test_the_walk_finds_the_numeric_options(parser):
    names = {n for n, _ in _numeric(parser)}
    assert {"semmatch evaluate --min-overlap", "semmatch simulate --margin", "semmatch panoptic segment --min-vertices",
            "semmatch train --lr", "semmatch adapt --upper-share", "semmatch transfer --jobs",
            "semmatch reconstruct --voxel-size"} <= names
    assert len(names) >= 80


def test_every_numeric_option_is_a_validated_number(parser):
    plain = [n for n, a in _numeric(parser) if not hasattr(a.type, "range_text")]
    assert not plain, f"numeric options without semmatch.cli.common.number(): {plain}"


def _below(t) -> str:
    return str(t.lo - 1) if t.kind is int else repr(t.lo - max(1e-6, abs(t.lo) * 1e-6))


def _above(t) -> str:
    return str(t.hi + 1) if t.kind is int else repr(t.hi + max(1e-6, abs(t.hi) * 1e-6))


def test_every_numeric_option_refuses_nan_inf_and_values_out_of_its_range(parser):
    for name, a in _numeric(parser):
        t = a.type
        for bad in ("nan", "inf", "-inf", "NaN", "x"):
            with pytest.raises(argparse.ArgumentTypeError):
                t(bad)
        if t.lo is not None:
            with pytest.raises(argparse.ArgumentTypeError, match="must be"):
                t(_below(t))
            if t.lo_open:
                with pytest.raises(argparse.ArgumentTypeError):
                    t(str(t.kind(t.lo)))
            else:
                assert t(str(t.kind(t.lo))) == t.lo, name
        if t.hi is not None:
            with pytest.raises(argparse.ArgumentTypeError, match="must be"):
                t(_above(t))
            assert t(str(t.kind(t.hi))) == t.hi or t.hi_open, name
        default = a.default if not isinstance(a.default, list) else (a.default or [None])[0]
        if isinstance(default, int | float) and not isinstance(default, bool):
            assert t(str(default)) == default, f"{name}: its default {default} is outside its own range"


def test_every_visible_numeric_option_states_its_range_in_the_help(parser):
    missing = []
    for name, p in walk_parsers(parser):
        fmt = p._get_formatter()
        for a in p._actions:
            if a.help == argparse.SUPPRESS or not hasattr(a.type, "range_text") or not a.type.range_text:
                continue
            if a.type.range_text not in fmt._expand_help(a):
                missing.append(f"{name} {a.option_strings}")
    assert not missing, missing


def test_the_ranges_the_issue_names(parser):
    by_name = dict(_numeric(parser))
    assert by_name["semmatch evaluate --min-overlap"].type.range_text == "0 to 1"
    assert by_name["semmatch adapt --upper-share"].type.range_text == "0 to 1"
    assert by_name["semmatch simulate --margin"].type.range_text == ">= 0"
    assert by_name["semmatch panoptic segment --min-vertices"].type.range_text == ">= 1"
    assert by_name["semmatch train --lr"].type.range_text == "> 0"
    assert by_name["semmatch transfer --jobs"].type.range_text == ">= 1"
    for name, a in by_name.items():
        if name.endswith("--voxel-size") or name.endswith("camera-height"):
            assert a.type.range_text == "> 0", name


@pytest.mark.parametrize("argv,flag", [
    (["evaluate", "a.ply", "b.ply", "--min-overlap", "nan"], "--min-overlap"),
    (["evaluate", "a.ply", "b.ply", "--min-overlap", "2"], "--min-overlap"),
    (["simulate", "--out", "x", "--margin", "-1"], "--margin"),
    (["panoptic", "segment", "m.ply", "--out", "o.ply", "--min-vertices", "-5"], "--min-vertices"),
    (["train", "--out", "m.pt", "--lr", "nan"], "--lr"),
    (["adapt", "--model", "n.pt", "--out", "a.pt", "--upper-share", "1.5"], "--upper-share"),
    (["transfer", "S", "--map", "m.ply", "--out", "o", "--jobs", "0"], "--jobs"),
])
def test_a_bad_number_is_a_usage_error_of_the_verb(capsys, argv, flag):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    verb = " ".join(argv[:2] if argv[0] == "panoptic" else argv[:1])
    assert err.startswith(f"usage: semmatch {verb} "), err
    assert f"argument {flag}: must be" in err, err


def test_a_mistyped_option_reports_the_verbs_usage(capsys):
    for argv, verb in ((["transfer", "S", "--map", "m.ply", "--method", "dbscan", "--out", "o", "--jbos", "2"], "transfer"),
                       (["panoptic", "evaluate", "a.ply", "b.ply", "--voxelsize", "0.1"], "panoptic evaluate")):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith(f"usage: semmatch {verb} "), err
        assert f"semmatch {verb}: error: unrecognized arguments: " in err, err


def test_train_recipe_and_its_old_spelling(parser, capsys):
    assert parser.parse_args(["train", "--out", "m.pt", "--recipe", "full"]).recipe == "full"
    capsys.readouterr()
    assert parser.parse_args(["train", "--out", "m.pt", "--profile", "full"]).recipe == "full"
    assert "--profile is deprecated; use --recipe" in capsys.readouterr().err
    shown = [o for a in parser._subparsers._group_actions[0].choices["train"]._actions
             if a.help != argparse.SUPPRESS for o in a.option_strings]
    assert "--recipe" in shown and "--profile" not in shown
