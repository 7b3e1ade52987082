"""One command line: the same spelling for the same thing, help on every option."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from semmatch.cli import build_parser, main


def _parsers(parser: argparse.ArgumentParser, name: str = "semmatch"):
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


def test_every_option_has_help_text():
    missing = []
    for name, p in _parsers(build_parser()):
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction | argparse._HelpAction | argparse._VersionAction):
                continue
            if a.help is None or (a.help != argparse.SUPPRESS and not a.help.strip()):
                missing.append(f"{name} {'/'.join(a.option_strings) or a.dest}")
    assert not missing, "options without help: " + ", ".join(missing)


def test_progress_flag_is_spelled_quiet_everywhere():
    for name, p in _parsers(build_parser()):
        opts = {o for a in p._actions for o in a.option_strings}
        if "--no-progress" in opts or "--quiet" in opts:
            assert {"--quiet", "--no-progress"} <= opts, name  # --quiet, with the old spelling as an alias
            shown = [a for a in p._actions if "--no-progress" in a.option_strings]
            assert all(a.help == argparse.SUPPRESS for a in shown), name


@pytest.mark.parametrize("argv", [["transfer", "S", "--map", "m.ply", "--method", "dbscan", "--out", "o"],
                                  ["transfer", "--sequence", "S", "--map", "m.ply", "--method", "dbscan", "--out", "o"]])
def test_the_sequence_is_positional_with_the_old_flag_as_an_alias(argv):
    from semmatch.cli import sequence_arg

    args = build_parser().parse_args(argv)
    assert sequence_arg(args) == "S"


def test_missing_sequence_is_a_clear_error(capsys):
    assert main(["transfer", "--map", "m.ply", "--method", "dbscan", "--out", "o"]) == 2
    assert "SEQ is required" in capsys.readouterr().err


def test_simulate_camera_step(tmp_path, capsys):
    """``--camera-step``: the robot's steps between frames stay within it; a bad step is refused."""
    from semmatch.cli import main
    from semmatch.io import read_sequence

    assert main(["simulate", "--scene-kind", "office", "--seed", "2", "--pair", "--frames", "6", "--camera-step",
                 "0.4", "--image-size", "32x24", "--out", str(tmp_path / "pair"), "--quiet"]) == 0
    for name in ("upper", "lower"):
        xy = np.stack([f.pose[:2, 3] for f in read_sequence(tmp_path / "pair" / name)])
        steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        assert steps.max() <= 0.4 + 1e-6 and steps.max() > 0.15  # longer than the default step allows
    with pytest.raises(SystemExit) as e:  # refused while parsing (semmatch.cli.common.number)
        main(["simulate", "--scene-kind", "office", "--camera-step", "0", "--frames", "3",
              "--out", str(tmp_path / "x"), "--quiet"])
    assert e.value.code == 2
    assert "--camera-step: must be > 0" in capsys.readouterr().err
