"""The one grammar of the ``semmatch`` command line: every argument two verbs share is added here.

* Sizes of images are ``--image-size WxH`` (:func:`add_image_size`), heights of cameras
  ``--camera-height`` in metres (:func:`add_camera_height`), procedural scenes ``--scene-kind``
  (:func:`add_scene_kind`, :func:`add_scene_kinds`).
* Every verb prints its result as a sentence or table, or as one JSON object on stdout with
  ``--json`` (:func:`add_json`, :func:`emit`); every long verb (:data:`LONG_VERBS`) shows progress
  on stderr and hides it with ``--quiet`` (:func:`add_quiet`).
* Old spellings stay as hidden aliases that still work and print a one-line note on stderr
  (:class:`DeprecatedAlias`, :func:`add_alias`).
* British spellings are accepted wherever the canonical name is American, for option names and
  for values of a choice list (``--method 3d-neighbourhood``), and turned into the canonical
  spelling at parse time (:func:`accept_british_spellings`, run on the whole parser).
* Help lines state a default once (:class:`HelpFormatter`).
* Every verb that takes a sequence opens any recording layout of the reader registry
  (:mod:`semmatch.io.readers`) with the same recording options (``--frames START:STOP``,
  ``--intrinsics``, ``--estimate-poses``, bag topics): :func:`add_recording_options`,
  :func:`open_sequence`.

Size: over 600 lines because it is the one place of the command line's grammar (the arguments
every verb shares, their parsing and the output conventions); split, the verbs would import
their shared options from several modules and two of them could drift apart.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Callable
from typing import Any, NamedTuple

__all__ = ["LONG_VERBS", "ImageSize", "HelpFormatter", "RawDescriptionHelpFormatter", "Parser", "DeprecatedAlias",
           "add_alias", "add_image_size", "add_camera_height", "add_scene_kind", "add_scene_kinds", "add_json",
           "add_quiet", "add_output_flags", "add_sequence", "sequence_arg", "add_recording_options", "open_sequence",
           "frame_range", "number", "image_size", "emit", "emit_table",
           "british", "accept_british_spellings", "walk_parsers", "add_index_cache", "index_cache_options"]

#: the verbs that run long enough to want a progress display (on stderr) and ``--quiet`` to hide it;
#: the benchmarks are left out (they time their work, and print nothing until the numbers)
LONG_VERBS: tuple[str, ...] = ("simulate", "train", "adapt", "predict", "reconstruct", "align", "transfer",
                               "panoptic reference", "panoptic transfer", "convert", "replay")


# ----------------------------------------------------------------------------- help
class HelpFormatter(argparse.HelpFormatter):
    """One style for every help line: what an option takes and its default, in one parenthesis at
    the end, ``(RANGE; default: X)``.

    The range is that of a :func:`number` option (``> 0``, ``0 to 1``, ...) unless the text states
    it already; ``default: X`` is appended only where the help text does not mention a default
    itself (help texts that describe one write ``(default: ...)`` too) and only for a default
    worth stating (not None, False, True or empty).
    """

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if text == argparse.SUPPRESS:
            return text
        parts = []
        span = getattr(action.type, "range_text", None)
        if span and span not in text:
            described = re.search(r"\(default: [^()]*\)$", text)  # a default the text describes itself
            if described:
                return f"{text[:described.start()]}({span}; {text[described.start() + 1:]}"
            parts.append(span.replace("%", "%%"))
        default = action.default
        if not (re.search(r"\bdefault", text, re.IGNORECASE)
                or default is None or default is argparse.SUPPRESS or isinstance(default, bool)
                or (isinstance(default, list | tuple) and not default)
                or not (action.option_strings or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE))):
            parts.append("default: %(default)s")
        if not parts:
            return text
        return f"{text} ({'; '.join(parts)})" if text else "; ".join(parts)


class RawDescriptionHelpFormatter(argparse.RawDescriptionHelpFormatter, HelpFormatter):
    """:class:`HelpFormatter` that keeps the description's and epilog's line breaks."""


class Parser(argparse.ArgumentParser):
    """The ``semmatch`` parser class: :class:`HelpFormatter` unless a verb names another
    (sub-parsers are made of the same class).

    A verb's parser refuses an argument it does not know itself, with the verb's usage line
    (argparse would hand it up to ``semmatch``'s parser, whose usage says nothing of the verb).
    """

    def __init__(self, *args: Any, formatter_class: type = HelpFormatter, **kwargs: Any) -> None:
        super().__init__(*args, formatter_class=formatter_class, **kwargs)

    def parse_known_args(self, args=None, namespace=None):
        namespace, extras = super().parse_known_args(args, namespace)
        verb = not any(isinstance(a, argparse._SubParsersAction) for a in self._actions)
        if extras and verb and self.prog.count(" ") >= 1:  # a verb (not ``semmatch`` itself)
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace, extras


def walk_parsers(parser: argparse.ArgumentParser, name: str = "semmatch"):
    """Yield ``(command, parser)`` for ``parser`` and every sub-parser below it, depth first.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    name : str
        The command of ``parser`` itself; sub-commands are named ``"NAME VERB"``.

    Yields
    ------
    tuple of (str, argparse.ArgumentParser)
    """
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from walk_parsers(sub, f"{name} {sub_name}")


# ----------------------------------------------------------------------------- old spellings
class DeprecatedAlias(argparse.Action):
    """A hidden old spelling of an option: it stores into the canonical option's ``dest`` and
    prints ``PROG: note: OLD is deprecated; use NEW`` on stderr.

    Parameters
    ----------
    option_strings, dest
        As for any argparse action.
    canonical : str
        The spelling to use instead (for the note).
    combine : callable, optional
        ``combine(current, value) -> new``: how the value joins the one already parsed (one
        component of a size given by two old options); default: the value replaces it.
    nargs, const, type, choices, metavar
        As for ``store`` (``nargs=0`` with ``const``: as ``store_const``).
    """

    def __init__(self, option_strings: list[str], dest: str, *, canonical: str,
                 combine: Callable[[Any, Any], Any] | None = None, nargs: int | str | None = None,
                 const: Any = None, type: Callable[[str], Any] | None = None, choices=None,
                 metavar: str | tuple | None = None, default: Any = argparse.SUPPRESS, required: bool = False,
                 help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=nargs, const=const, default=default, type=type,
                         choices=choices, required=required, help=argparse.SUPPRESS, metavar=metavar)
        self.canonical = canonical
        self.combine = combine

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        print(f"{parser.prog}: note: {option_string} is deprecated; use {self.canonical}", file=sys.stderr)
        value = self.const if self.nargs == 0 else values
        if self.combine is not None:
            value = self.combine(getattr(namespace, self.dest, None), value)
        setattr(namespace, self.dest, value)


def add_alias(container, *old: str, canonical: str, dest: str, **kwargs: Any) -> argparse.Action:
    """Add hidden, deprecated spellings ``old`` of the option ``canonical`` (same ``dest``).

    Parameters
    ----------
    container : argparse.ArgumentParser or argument group
        Where the canonical option was added (a mutually exclusive group keeps the alias exclusive).
    *old : str
        The old option strings.
    canonical : str
        The option to use instead, as the note names it (e.g. ``"--image-size WxH"``).
    dest : str
        The canonical option's ``dest``.
    **kwargs
        ``nargs``, ``const``, ``type``, ``combine``, ... of :class:`DeprecatedAlias`.

    Returns
    -------
    argparse.Action
    """
    return container.add_argument(*old, action=DeprecatedAlias, dest=dest, canonical=canonical, **kwargs)


# ----------------------------------------------------------------------------- values
class ImageSize(NamedTuple):
    """An image size in pixels, written ``WxH`` (``str(ImageSize(640, 480)) == "640x480"``)."""

    width: int | None
    height: int | None

    def __str__(self) -> str:
        return f"{self.width}x{self.height}"


def image_size(text: str) -> ImageSize:
    """An argparse ``type``: ``"640x480"`` as ``ImageSize(640, 480)`` (whole numbers >= 1).

    Parameters
    ----------
    text : str

    Returns
    -------
    ImageSize

    Raises
    ------
    argparse.ArgumentTypeError
        Not ``WxH`` with two whole numbers >= 1 (argparse turns it into a usage error, exit 2).
    """
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or min(int(m[1]), int(m[2])) < 1:
        raise argparse.ArgumentTypeError(f"must look like WxH, e.g. 640x480 (whole numbers >= 1); got {text!r}")
    return ImageSize(int(m[1]), int(m[2]))


image_size.__name__ = "WxH"  # argparse names the type in its messages


def number(kind: type = float, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
           hi_open: bool = False):
    """An argparse ``type`` that parses a ``kind`` (int or float) and refuses it outside its range.

    Every numeric option of every verb takes its values through this type: NaN and infinities are
    always refused, and the help line states the range (:class:`HelpFormatter`).

    Parameters
    ----------
    kind : type
        ``int`` or ``float``.
    lo, hi : float, optional
        Bounds, inclusive unless ``lo_open`` / ``hi_open``.
    lo_open, hi_open : bool
        ``lo`` (``hi``) itself is refused.

    Returns
    -------
    callable
        For ``add_argument(type=...)``: argparse turns its ``ArgumentTypeError`` into a usage
        error (exit 2) that names the flag. It carries ``kind``, ``lo``, ``hi``, ``lo_open``,
        ``hi_open`` and ``range_text`` (e.g. ``"> 0"``, ``"0 to 1"``; empty when unbounded).
    """
    if kind not in (int, float):
        raise TypeError(f"number() parses int or float, not {kind!r}")
    low = "" if lo is None else f"{'>' if lo_open else '>='} {lo:g}"
    high = "" if hi is None else f"{'<' if hi_open else '<='} {hi:g}"
    if low and high and not (lo_open or hi_open):
        span = f"{lo:g} to {hi:g}"
    else:
        span = ", ".join(t for t in (low, high) if t)

    def parse(text: str):
        try:
            v = kind(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(f"expected {'a whole number' if kind is int else 'a number'}, "
                                             f"got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be a finite number{f' ({span})' if span else ''}, got {text!r}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            raise argparse.ArgumentTypeError(f"must be {low}, got {text}")
        if hi is not None and (v >= hi if hi_open else v > hi):
            raise argparse.ArgumentTypeError(f"must be {high}, got {text}")
        return v

    parse.__name__ = kind.__name__  # argparse names the type in its messages
    parse.kind, parse.lo, parse.hi, parse.lo_open, parse.hi_open = kind, lo, hi, lo_open, hi_open
    parse.range_text = span
    return parse


# ----------------------------------------------------------------------------- shared arguments
def add_image_size(parser, *, default: ImageSize | None = None, help: str = "image size in pixels",
                   flag: str = "--image-size", dest: str = "image_size", old: tuple[str, ...] = (),
                   old_split: tuple[str, str] | None = None) -> None:
    """``--image-size WxH`` (an :class:`ImageSize`), with the verb's old spellings as hidden aliases.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    default : ImageSize, optional
    help : str
    flag, dest : str
        The option and its ``dest`` (another size of the verb: ``--net-size``, ``net_size``).
    old : tuple of str
        Old spellings taking ``WxH`` too (``--size``).
    old_split : (str, str), optional
        Old options giving the width and the height apart (``("--width", "--height")``); each
        sets its half of the size, the other half kept (None when not given).
    """
    parser.add_argument(flag, dest=dest, type=image_size, default=default, metavar="WxH", help=help)
    if old:
        add_alias(parser, *old, canonical=f"{flag} WxH", dest=dest, type=image_size, metavar="WxH")
    if old_split:
        positive = number(int, lo=1)
        for i, opt in enumerate(old_split):
            add_alias(parser, opt, canonical=f"{flag} WxH", dest=dest, type=positive, combine=_half(i))


def _half(i: int) -> Callable[[Any, int], ImageSize]:
    """``combine`` of an old width (``i == 0``) or height (``i == 1``) option."""

    def combine(current: ImageSize | None, value: int) -> ImageSize:
        parts = list(current) if current is not None else [None, None]
        parts[i] = value
        return ImageSize(*parts)

    return combine


def add_camera_height(parser, *, default: float | None, help: str = "camera height above the floor in metres",
                      flag: str = "--camera-height", old: tuple[str, ...] = ()) -> None:
    """``--camera-height`` in metres (``flag`` for a second camera), old spellings as hidden aliases.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    default : float or None
    help : str
    flag : str
        ``--camera-height``, or e.g. ``--lower-camera-height``; ``dest`` follows the flag.
    old : tuple of str
        Old spellings (``--height``).
    """
    dest = flag.lstrip("-").replace("-", "_")
    metres = number(float, lo=0.0, lo_open=True)
    parser.add_argument(flag, dest=dest, type=metres, default=default, metavar="M", help=help)
    if old:
        add_alias(parser, *old, canonical=flag, dest=dest, type=metres, metavar="M")


def add_scene_kind(parser, *, default: str | None, help: str = "procedural scene kind",
                   old: tuple[str, ...] = ()) -> None:
    """``--scene-kind KIND`` (``dest`` ``scene_kind``), old spellings (``--kind``, ``--scene``) as
    hidden aliases.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group (a mutually exclusive one included)
    default : str or None
    help : str
    old : tuple of str
    """
    parser.add_argument("--scene-kind", dest="scene_kind", default=default, metavar="KIND", help=help)
    if old:
        add_alias(parser, *old, canonical="--scene-kind", dest="scene_kind", metavar="KIND")


def add_scene_kinds(parser, *, default: list[str] | None, help: str = "procedural scene kinds",
                    nargs: str = "*", old: tuple[str, ...] = ("--kinds",)) -> None:
    """``--scene-kinds KIND ...`` (``dest`` ``scene_kinds``), ``--kinds`` as a hidden alias.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    default : list of str or None
    help : str
    nargs : str
        ``"*"`` or ``"+"``.
    old : tuple of str
    """
    parser.add_argument("--scene-kinds", dest="scene_kinds", nargs=nargs, default=default, metavar="KIND", help=help)
    if old:
        add_alias(parser, *old, canonical="--scene-kinds", dest="scene_kinds", nargs=nargs, metavar="KIND")


def add_json(parser, what: str = "the result") -> None:
    """``--json``: print ``what`` as one JSON object on stdout instead of text (see :func:`emit`).

    Parameters
    ----------
    parser : argparse.ArgumentParser
    what : str
    """
    parser.add_argument("--json", action="store_true", help=f"print {what} as one JSON object")


def add_quiet(parser, what: str = "the progress bars") -> None:
    """``--quiet``: hide the progress display (``--no-progress`` is a hidden, deprecated alias).

    Parameters
    ----------
    parser : argparse.ArgumentParser
    what : str
        What is hidden, for the help line.
    """
    parser.add_argument("--quiet", action="store_true", help=f"hide {what}")
    add_alias(parser, "--no-progress", canonical="--quiet", dest="quiet", nargs=0, const=True)


def add_index_cache(parser) -> None:
    """``--index-cache WHERE`` and ``--no-index-cache``: where the map's index cache goes.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    """
    parser.add_argument("--index-cache", default="user", metavar="WHERE",
                        help="where the map's index cache goes: 'user' (the user cache folder, "
                             "$SEMMATCH_CACHE_DIR/index when that is set), 'beside' (a hidden .MAP.index-KEY.npz "
                             "beside the map) or a folder (default: user)")
    parser.add_argument("--no-index-cache", action="store_true",
                        help="neither read nor write the map's index cache (also off with SEMMATCH_NO_INDEX_CACHE)")


def index_cache_options(args: argparse.Namespace) -> dict:
    """The keywords of :func:`semmatch.transfer.load_index` that :func:`add_index_cache` set."""
    return {"cache": not args.no_index_cache, "cache_dir": args.index_cache}


def add_output_flags(parser, *, json_what: str = "the result", quiet: str | None = None) -> None:
    """The output flags of a verb: ``--json``, and ``--quiet`` for a long verb.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    json_what : str
        What ``--json`` prints.
    quiet : str, optional
        What ``--quiet`` hides (``"the progress bars"``); None: no ``--quiet`` (a short verb).
    """
    if quiet is not None:
        add_quiet(parser, quiet)
    add_json(parser, json_what)


def add_sequence(parser, help: str, *, recording: bool = True) -> None:
    """The sequence as the first positional argument, as every verb takes it (``--sequence SEQ``
    is a hidden, deprecated alias), and the recording options (:func:`add_recording_options`);
    read it with :func:`sequence_arg`, open it with :func:`open_sequence`.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    help : str
    recording : bool
        Also add the recording options.
    """
    parser.add_argument("sequence", nargs="?", metavar="SEQ", help=help)
    add_alias(parser, "--sequence", canonical="the positional SEQ", dest="sequence_flag", metavar="SEQ",
              default=None)
    if recording:
        add_recording_options(parser)


def frame_range(text: str) -> slice:
    """An argparse ``type``: ``"START:STOP"`` (either may be left out) as ``slice(START, STOP)``.

    Parameters
    ----------
    text : str
        E.g. ``"0:250"`` (frames 0 to 249), ``"250:"``, ``":100"``.

    Returns
    -------
    slice

    Raises
    ------
    argparse.ArgumentTypeError
        Not two whole numbers >= 0 around one colon, or STOP <= START.
    """
    m = re.fullmatch(r"\s*(\d*)\s*:\s*(\d*)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"must look like START:STOP, e.g. 0:250 (whole numbers >= 0); got {text!r}")
    start, stop = (int(g) if g else None for g in m.groups())
    if start is not None and stop is not None and stop <= start:
        raise argparse.ArgumentTypeError(f"STOP must be above START (frames START..STOP-1); got {text!r}")
    return slice(start, stop)


frame_range.__name__ = "START:STOP"  # argparse names the type in its messages

#: the bag topic options (:func:`add_recording_options`), passed to a recording's reader only when given
TOPIC_OPTIONS: tuple[tuple[str, str], ...] = (
    ("--color-topic", "colour image topic"), ("--depth-topic", "depth image topic"),
    ("--camera-info-topic", "camera_info topic (intrinsics)"),
    ("--pose-topic", "pose topic (odometry, PoseStamped, TransformStamped, or /tf)"),
    ("--pose-frames", "poses from /tf + /tf_static: WORLD:CAMERA (or WORLD: the images' frame as CAMERA)"))


def add_recording_options(parser, *, frames: bool = True,
                          estimate_help: str = "pose a recording without poses by RGB-D odometry (the recorded "
                                               "poses are ignored); the trajectory is cached in the user cache "
                                               "folder, keyed by the frames and the odometry settings") -> None:
    """The options of every verb that reads a recording (any layout of :mod:`semmatch.io.readers`).

    ``--frames START:STOP`` (a frame range, for every layout), ``--intrinsics FILE.json`` (the
    camera, for a recording without one), ``--estimate-poses`` and the bag topics
    (:data:`TOPIC_OPTIONS`); read them with :func:`open_sequence`.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
        A parser gets a "recording" group; a group (a verb's "in a home") takes the options itself.
    frames : bool
        Add ``--frames`` (False for a verb whose ``--frames`` means something else).
    estimate_help : str
        Help of ``--estimate-poses``.
    """
    g = parser if isinstance(parser, argparse._ArgumentGroup) else parser.add_argument_group(
        "recording", "how the sequence is read (any layout: semmatch sequence, TUM RGB-D, 7-Scenes, plain folder, "
        "and any layout registered in semmatch.io.readers)")
    if frames:
        g.add_argument("--frames", type=frame_range, default=None, metavar="START:STOP",
                       help="use only frames START..STOP-1 of the recording (either end may be left out; "
                            "default all)")
    g.add_argument("--intrinsics", default=None, metavar="FILE.json",
                   help="the camera (an intrinsics.json) for a recording that names none")
    g.add_argument("--estimate-poses", action="store_true", help=estimate_help)
    for flag, what in TOPIC_OPTIONS:
        g.add_argument(flag, default=None, metavar="TOPIC", help=f"bags: the {what}")


def open_sequence(args: argparse.Namespace, path: str | None = None, *, needs_poses: bool = False,
                  odometry: dict | None = None, **options: Any):
    """Open the verb's sequence (any registered layout) with its recording options.

    Parameters
    ----------
    args : argparse.Namespace
        With the options of :func:`add_recording_options` (missing ones count as not given).
    path : str, optional
        The recording (default :func:`sequence_arg`).
    needs_poses : bool
        The verb places frames in the world: a recording without a pose for every frame is
        refused, naming ``--estimate-poses``, unless that flag was given.
    odometry : dict, optional
        ``--estimate-poses`` settings (:func:`semmatch.poses.recording_poses.estimate_recording_poses`:
        ``residual``, ``pose_graph``, ``prior``, ``device``).
    **options
        More reader options (``labels``).

    Returns
    -------
    sequence of Frame
        The reader, or a view with the estimated poses; with ``--estimate-poses`` its
        ``pose_estimate`` is the estimate's ``info`` (``cached``, ``ground_truth`` ...).

    Raises
    ------
    ValueError, FileNotFoundError
        See :func:`semmatch.io.readers.open_recording`; no poses (the message names
        ``--estimate-poses``).
    """
    from semmatch.io.readers import SequenceView, missing_poses, open_recording

    path = path or sequence_arg(args)
    frames = getattr(args, "frames", None)
    opts = {"frames": frames if isinstance(frames, slice) else None, **options}
    if getattr(args, "intrinsics", None):
        from semmatch.io import read_intrinsics

        opts["intrinsics"] = read_intrinsics(args.intrinsics)
    for flag, _ in TOPIC_OPTIONS:
        opts[flag[2:].replace("-", "_")] = getattr(args, flag[2:].replace("-", "_"), None)
    seq = open_recording(path, **opts)
    if getattr(args, "estimate_poses", False):
        from semmatch.poses.recording_poses import estimate_recording_poses

        poses, info = estimate_recording_poses(seq, name=str(path), progress=not getattr(args, "quiet", False),
                                               **(odometry or {}))
        seq = SequenceView(seq, poses=poses)
        seq.pose_estimate = info
    elif needs_poses and (why := missing_poses(seq)):
        raise ValueError(f"{path} {why}; pass --estimate-poses to pose it by RGB-D odometry (cached for the next "
                         "run), or give a recording with poses")
    return seq


def sequence_arg(args: argparse.Namespace) -> str:
    """The sequence given positionally or with ``--sequence`` (a clear error when neither or both).

    Parameters
    ----------
    args : argparse.Namespace

    Returns
    -------
    str

    Raises
    ------
    ValueError
        No sequence, or two different ones.
    """
    pos, flag = getattr(args, "sequence", None), getattr(args, "sequence_flag", None)
    if pos and flag and pos != flag:
        raise ValueError(f"two sequences given ({pos} and --sequence {flag}); give SEQ once")
    if not (pos or flag):
        verb = " ".join(v for v in (getattr(args, "verb", None), getattr(args, "action", None)) if v)
        raise ValueError(f"the sequence folder SEQ is required (semmatch {verb} SEQ ...)")
    return pos or flag


# ----------------------------------------------------------------------------- output
def _jsonable(value: Any) -> Any:
    """``json.dumps`` ``default``: paths and other objects as text, NumPy values as Python ones."""
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        return value.tolist()
    if isinstance(value, set | frozenset):
        return sorted(value, key=str)
    return str(value)


def emit(result: dict, as_json: bool, text: str) -> int:
    """Print ``result`` as one JSON object (``as_json``) or ``text``; return 0 (the exit code).

    Parameters
    ----------
    result : dict
        JSON-able, paths and NumPy values included.
    as_json : bool
        The verb's ``--json``.
    text : str
        The human form: a sentence or a table.

    Returns
    -------
    int
    """
    print(json.dumps(result, default=_jsonable) if as_json else text)
    return 0


def emit_table(df, as_json: bool, key: str = "predictions") -> int:
    """Print a results table (one row per prediction): as text, or as ``{key: {row: {column: value}}}``.

    Parameters
    ----------
    df : pandas.DataFrame
        Indexed by the row names.
    as_json : bool
        The verb's ``--json`` (NaN becomes null).
    key : str

    Returns
    -------
    int
        0, the exit code.
    """
    import pandas as pd

    with pd.option_context("display.width", 200, "display.max_columns", 50):
        text = df.to_string(float_format=lambda v: f"{v:.4f}")
    return emit({key: json.loads(df.to_json(orient="index"))} if as_json else {}, as_json, text)


# ----------------------------------------------------------------------------- British spellings
#: American -> British words of option names and choice values (whole words between - and _)
_BRITISH = {"neighbor": "neighbour", "neighbors": "neighbours", "neighborhood": "neighbourhood",
            "neighborhoods": "neighbourhoods", "color": "colour", "colors": "colours", "colored": "coloured",
            "normalize": "normalise", "normalized": "normalised", "normalization": "normalisation",
            "center": "centre", "centers": "centres", "centered": "centred", "gray": "grey",
            "labeling": "labelling", "labelings": "labellings", "labeled": "labelled",
            "optimize": "optimise", "optimizer": "optimiser", "visualize": "visualise", "analyze": "analyse"}


def british(text: str) -> str:
    """``text`` with its American words (between ``-``, ``_`` and spaces) in British spelling.

    Parameters
    ----------
    text : str
        An option string or a choice, e.g. ``"3d-neighborhood"``.

    Returns
    -------
    str
        E.g. ``"3d-neighbourhood"``; ``text`` itself when it has no American word.
    """
    return "".join(_BRITISH.get(part.lower(), part) if part.isalpha() else part
                   for part in re.split(r"([-_ ])", text))


def _canonical_choice(inner: Callable[[str], Any] | None, aliases: dict[str, str]) -> Callable[[str], Any]:
    """An argparse ``type`` that turns a British spelling of a choice into the canonical one first."""

    def parse(text: str):
        text = aliases.get(text, text)
        return inner(text) if inner is not None else text

    parse.__name__ = getattr(inner, "__name__", "str")
    parse.british_aliases = aliases
    return parse


def accept_british_spellings(parser: argparse.ArgumentParser) -> None:
    """Make every parser below ``parser`` accept British spellings (run once on the whole parser).

    An option whose name has an American word (``--labelings``) also answers to the British
    spelling (``--labellings``, hidden); a choice list with an American word
    (``3d-neighborhood``) also takes the British spelling, turned into the canonical one at
    parse time so that everything downstream sees one name.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    """
    for _, p in walk_parsers(parser):
        for action in list(p._actions):
            if isinstance(action, argparse._SubParsersAction):
                continue
            for opt in list(action.option_strings):
                alt = british(opt)
                if alt != opt and alt not in p._option_string_actions:
                    p._option_string_actions[alt] = action  # accepted, not listed in the help
            if action.choices is not None and all(isinstance(c, str) for c in action.choices):
                aliases = {british(c): c for c in action.choices if british(c) != c}
                if aliases and not hasattr(action.type, "british_aliases"):
                    action.type = _canonical_choice(action.type, aliases)
