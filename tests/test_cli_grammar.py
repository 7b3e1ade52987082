"""One grammar for the command line: every verb and sub-verb of ``semmatch``, found by walking the
parser (not from a list), spells the same thing the same way.

* image sizes are ``--image-size WxH``, camera heights ``--camera-height`` (metres), scene kinds
  ``--scene-kind``; the old spellings are hidden aliases that still parse, to the same namespace,
  with a one-line deprecation note on stderr;
* a help line states its default at most once;
* every verb has ``--json`` (one JSON object on stdout); every long verb
  (:data:`semmatch.cli.common.LONG_VERBS`) has ``--quiet``;
* a choice or an option name in American spelling takes the British one too, turned into the
  canonical name at parse time.
"""

from __future__ import annotations

import argparse
import json
import re

import pytest

from semmatch.cli import VERBS, build_parser, main
from semmatch.cli.common import LONG_VERBS, ImageSize, british, walk_parsers

#: option names that meant different things in different verbs, or the same thing under two names
OLD_SPELLINGS = {"--size", "--width", "--height", "--kind", "--kinds", "--scene", "--lower-height", "--net-width",
                 "--net-height", "--no-progress", "--sequence"}


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return build_parser()


def _has_subcommands(p: argparse.ArgumentParser) -> bool:
    return any(isinstance(a, argparse._SubParsersAction) for a in p._actions)


def _verbs(parser) -> dict[str, argparse.ArgumentParser]:
    """Every command that runs something (``semmatch simulate``, ``semmatch bench render``, ...)."""
    return {name: p for name, p in walk_parsers(parser) if not _has_subcommands(p)}


def _visible(p: argparse.ArgumentParser):
    return [a for a in p._actions if a.help != argparse.SUPPRESS and not isinstance(a, argparse._HelpAction)]


def _options(p: argparse.ArgumentParser) -> set[str]:
    return {o for a in _visible(p) for o in a.option_strings}


def test_the_walk_reaches_every_verb_and_sub_verb(parser):
    verbs = _verbs(parser)
    tops = {name.split()[1] for name in verbs}
    assert tops == set(VERBS)
    assert {"semmatch panoptic reference", "semmatch panoptic transfer", "semmatch bench render",
            "semmatch bench fusion"} <= set(verbs)
    assert len(verbs) >= 18, sorted(verbs)
    for name, p in walk_parsers(parser):
        assert p.format_help(), name  # every help page renders


def test_old_spellings_are_hidden_and_one_name_means_one_thing(parser):
    for name, p in _verbs(parser).items():
        shown = _options(p)
        assert not shown & OLD_SPELLINGS, f"{name}: {sorted(shown & OLD_SPELLINGS)}"
        # a width or height is part of --image-size WxH; a height in metres is a --*camera-height
        assert all("width" not in o for o in shown), name
        assert all(o.endswith("camera-height") for o in shown if "height" in o), name
        for a in _visible(p):
            if a.metavar == "WxH":
                assert a.type("32x24") == ImageSize(32, 24), (name, a.option_strings)


def test_each_help_line_states_its_default_at_most_once(parser):
    twice = []
    for name, p in walk_parsers(parser):
        fmt = p._get_formatter()
        for a in _visible(p):
            text = fmt._expand_help(a) if a.help else ""
            if len(re.findall(r"\bdefault\b", text, re.IGNORECASE)) > 1:
                twice.append(f"{name} {'/'.join(a.option_strings) or a.dest}: {text}")
    assert not twice, "\n".join(twice)


def test_every_verb_has_json(parser):
    missing = [name for name, p in _verbs(parser).items() if "--json" not in _options(p)]
    assert not missing, missing


def test_the_long_verbs_and_only_they_have_quiet(parser):
    verbs = _verbs(parser)
    long = {f"semmatch {v}" for v in LONG_VERBS}
    assert long <= set(verbs), sorted(long - set(verbs))
    with_quiet = {name for name, p in verbs.items() if "--quiet" in _options(p)}
    assert with_quiet == long


def test_american_choices_and_option_names_take_british_spellings(parser):
    choices = names = 0
    for name, p in walk_parsers(parser):
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                continue
            for c in a.choices or ():
                if isinstance(c, str) and british(c) != c:
                    assert a.type is not None and a.type(british(c)) == c, (name, c)
                    choices += 1
            for o in a.option_strings:
                if british(o) != o:
                    assert p._option_string_actions.get(british(o)) is a, (name, o)
                    names += 1
    assert choices >= 3 and names >= 1  # transfer, panoptic transfer, adapt; --labelings


@pytest.mark.parametrize("old,new,notes", [
    (["simulate", "--kind", "office", "--height", "0.2", "--lower-height", "0.3", "--size", "32x24", "--kinds",
      "office", "--out", "x"],
     ["simulate", "--scene-kind", "office", "--camera-height", "0.2", "--lower-camera-height", "0.3",
      "--image-size", "32x24", "--scene-kinds", "office", "--out", "x"],
     ["--kind", "--height", "--lower-height", "--size", "--kinds"]),
    (["train", "--out", "m.pt", "--width", "64", "--height", "48", "--net-width", "32", "--net-height", "24",
      "--kinds", "office", "--no-progress"],
     ["train", "--out", "m.pt", "--image-size", "64x48", "--net-size", "32x24", "--scene-kinds", "office", "--quiet"],
     ["--width", "--height", "--net-width", "--net-height", "--kinds", "--no-progress"]),
    (["bench", "fusion", "--width", "160", "--scene", "office"],
     ["bench", "fusion", "--image-size", "160x480", "--scene-kind", "office"], ["--width", "--scene"]),
    (["bench", "render", "--kind", "office", "--size", "80x60", "--height", "0.5"],
     ["bench", "render", "--scene-kind", "office", "--image-size", "80x60", "--camera-height", "0.5"],
     ["--kind", "--size", "--height"]),
    (["bench", "transfer", "--height", "0.3"], ["bench", "transfer", "--camera-height", "0.3"], ["--height"]),
    (["bench", "metrics", "--scene", "office"], ["bench", "metrics", "--scene-kind", "office"], ["--scene"]),
    (["adapt", "--model", "n.pt", "--out", "a.pt", "--kinds", "office"],
     ["adapt", "--model", "n.pt", "--out", "a.pt", "--scene-kinds", "office"], ["--kinds"]),
])
def test_old_spellings_parse_to_the_same_namespace_with_a_note(parser, capsys, old, new, notes):
    capsys.readouterr()
    assert vars(parser.parse_args(new)) == vars(parser.parse_args(old))
    err = capsys.readouterr().err.splitlines()
    assert len(err) == len(notes)
    for line, flag in zip(err, notes):
        assert re.fullmatch(rf"semmatch [a-z ]+: note: {flag} is deprecated; use --[a-z-]+( WxH)?", line), line


def test_old_sequence_flag_parses_and_notes(parser, capsys):
    from semmatch.cli import sequence_arg

    args = parser.parse_args(["panoptic", "reference", "--sequence", "S", "--out", "o.ply"])
    assert sequence_arg(args) == "S"
    assert "--sequence is deprecated" in capsys.readouterr().err


def test_british_values_reach_the_library_in_the_canonical_spelling(parser, capsys):
    for argv, dest in ((["transfer", "S", "--map", "m.ply", "--method", "3d-neighbourhood", "--out", "o"], "method"),
                       (["panoptic", "transfer", "S", "--map", "m.ply", "--method", "3d-neighbourhood", "--out", "o"],
                        "method"),
                       (["adapt", "--model", "n.pt", "--out", "a.pt", "--source", "3d-neighbourhood"], "source")):
        assert getattr(parser.parse_args(argv), dest) == "3d-neighborhood"
    assert parser.parse_args(["bench", "transfer", "--methods", "3d-neighbourhood", "dbscan"]).methods == [
        "3d-neighborhood", "dbscan"]
    assert parser.parse_args(["bench", "fusion", "--labellings", "2"]).labelings == 2
    assert capsys.readouterr().err == ""  # British spellings are not deprecated


def test_a_half_given_old_size_is_a_clear_error(capsys):
    assert main(["train", "--out", "m.pt", "--width", "64"]) == 2
    assert "give both --width and --height (better: --image-size WxH)" in capsys.readouterr().err


@pytest.mark.parametrize("text", ["axb", "640", "0x480", "3x"])
def test_a_bad_image_size_is_a_usage_error(capsys, text):
    with pytest.raises(SystemExit) as e:
        main(["simulate", "--out", "x", "--image-size", text])
    assert e.value.code == 2
    assert "argument --image-size: must look like WxH" in capsys.readouterr().err


def _json_of(capsys, argv: list[str]) -> dict:
    capsys.readouterr()
    assert main(argv) == 0
    out = capsys.readouterr().out
    result = json.loads(out)
    assert isinstance(result, dict) and out.count("\n") == 1, out  # one object, on one line
    return result


def test_json_output_is_one_object(tmp_path, capsys):
    from semmatch.cli.bench.metrics import surface_maps
    from semmatch.io import write_map

    gt, _ = surface_maps(3000, scene_kind="office")
    write_map(tmp_path / "gt.ply", gt)
    res = _json_of(capsys, ["evaluate", str(tmp_path / "gt.ply"), str(tmp_path / "gt.ply"), "--json"])
    assert res["predictions"]["gt.ply"]["jaccard"] == pytest.approx(1.0)
    res = _json_of(capsys, ["show", str(tmp_path / "gt.ply"), "--html", str(tmp_path / "x.html"), "--plotlyjs", "cdn",
                            "--json"])
    assert res["html"] == str(tmp_path / "x.html")
    res = _json_of(capsys, ["bench", "metrics", "--vertices", "2000", "--repeat", "1", "--no-dict-loop",
                            "--voxel-size", "0.2", "--json"])
    assert res["n_vertices"] == 2000
    res = _json_of(capsys, ["simulate", "--scene-kind", "office", "--frames", "2", "--image-size", "32x24",
                            "--out", str(tmp_path / "seq"), "--quiet", "--json"])
    assert res["frames"] == 2 and res["camera_height"] == 1.6
    res = _json_of(capsys, ["reconstruct", str(tmp_path / "seq"), "--out", str(tmp_path / "m.ply"), "--quiet",
                            "--json"])
    assert res["vertices"] > 0
    # without --json: a sentence, not JSON
    assert main(["reconstruct", str(tmp_path / "seq"), "--out", str(tmp_path / "m.ply"), "--quiet"]) == 0
    assert re.fullmatch(r".*m\.ply: \d+ vertices, \d+ faces\n", capsys.readouterr().out)
