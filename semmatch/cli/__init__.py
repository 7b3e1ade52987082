"""``semmatch <verb>``: a thin command-line layer over the package.

Each verb lives in its own module of this package and exposes ``register(subparsers)``,
which adds its sub-parser and sets ``func`` (called with the parsed namespace, returning an
exit code). ``semmatch bench <what>`` benchmarks are registered the same way by modules
under :mod:`semmatch.cli.bench`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: verb modules, in the order ``semmatch --help`` lists them
VERBS = ("simulate", "train", "adapt", "predict", "reconstruct", "transfer", "evaluate", "panoptic", "show", "bench")


def add_quiet(parser: argparse.ArgumentParser, what: str = "the progress bars") -> None:
    """The one progress flag of every verb: ``--quiet`` (``--no-progress`` is kept as an alias)."""
    parser.add_argument("--quiet", action="store_true", help=f"hide {what}")
    parser.add_argument("--no-progress", dest="quiet", action="store_true", help=argparse.SUPPRESS)


def add_sequence(parser: argparse.ArgumentParser, help: str) -> None:
    """The sequence as the first positional argument, as every verb takes it (``--sequence SEQ``
    is kept as an alias); read it with :func:`sequence_arg`."""
    parser.add_argument("sequence", nargs="?", metavar="SEQ", help=help)
    parser.add_argument("--sequence", dest="sequence_flag", metavar="SEQ", help=argparse.SUPPRESS)


def sequence_arg(args: argparse.Namespace) -> str:
    """The sequence given positionally or with ``--sequence`` (a clear error when neither or both)."""
    pos, flag = getattr(args, "sequence", None), getattr(args, "sequence_flag", None)
    if pos and flag and pos != flag:
        raise ValueError(f"two sequences given ({pos} and --sequence {flag}); give SEQ once")
    if not (pos or flag):
        verb = " ".join(v for v in (getattr(args, "verb", None), getattr(args, "action", None)) if v)
        raise ValueError(f"the sequence folder SEQ is required (semmatch {verb} SEQ ...)")
    return pos or flag


def number(kind: type = float, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False):
    """An argparse ``type`` that parses a ``kind`` (int or float) and refuses it outside its range.

    Parameters
    ----------
    kind : type
        ``int`` or ``float``; NaN and infinities are refused.
    lo, hi : float, optional
        Inclusive bounds (``lo`` exclusive with ``lo_open``).

    Returns
    -------
    callable
        For ``add_argument(type=...)``: argparse turns its ``ArgumentTypeError`` into a usage
        error (exit 2) that names the flag.
    """
    import math

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, "
                                             f"got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            raise argparse.ArgumentTypeError(f"must be {'>' if lo_open else '>='} {lo:g}, got {text}")
        if hi is not None and v > hi:
            raise argparse.ArgumentTypeError(f"must be <= {hi:g}, got {text}")
        return v

    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


def build_parser() -> argparse.ArgumentParser:
    """The full ``semmatch`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="semmatch",
        description="3D semantic label transfer across human and robot viewpoints.",
    )
    from semmatch import __version__

    parser.add_argument("--version", action="version", version=f"semmatch {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.required = True
    for verb in VERBS:
        importlib.import_module(f"semmatch.cli.{verb}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``semmatch`` console script."""
    from concurrent.futures.process import BrokenProcessPool

    from semmatch.io.outputs import check_cli_paths, terminate_as_interrupt
    from semmatch.threads import configure

    try:  # threads set once, before the verbs load torch, Open3D or a BLAS (semmatch.threads)
        configure("cli")
    except ValueError as e:
        print(f"semmatch: error: {e}", file=sys.stderr)
        return 2
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with terminate_as_interrupt():  # SIGTERM, like Ctrl-C, runs the clean-up of temporary folders
            check_cli_paths(args)  # before any work: no output on, in or around an input
            return int(args.func(args) or 0)
    except BrokenProcessPool as e:  # a worker killed from outside (the out-of-memory killer, a kill -9)
        jobs = getattr(args, "jobs", None)
        print(f"semmatch {args.verb}: error: a worker process died before finishing its item ({e}); it was most "
              "likely killed by the system for lack of memory. Nothing half-written was left in place; rerun with "
              f"fewer worker processes{f' (--jobs {jobs} now)' if jobs else ''}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        what = "terminated (SIGTERM)" if type(e).__name__ == "Terminated" else "interrupted"
        print(f"semmatch {args.verb}: {what}; nothing half-written was left in place", file=sys.stderr)
        return 143 if what.startswith("terminated") else 130
    except (ValueError, FileNotFoundError, FileExistsError, KeyError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        print(f"semmatch {args.verb}: error: {msg}", file=sys.stderr)
        return 2
    except OSError as e:  # permissions, read-only or full disks, folders where files are expected
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        print(f"semmatch {args.verb}: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"semmatch {args.verb}: error: out of memory; the input is larger than this machine can "
              "hold at these settings (a map in millimetres instead of metres? a voxel size too small? "
              "an image size too large?)", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
