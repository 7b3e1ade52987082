"""``semmatch <verb>``: a thin command-line layer over the package.

Each verb lives in its own module of this package and exposes ``register(subparsers)``,
which adds its sub-parser and sets ``func`` (called with the parsed namespace, returning an
exit code). The arguments verbs share, and the grammar they follow (``--image-size WxH``,
``--camera-height``, ``--scene-kind``, ``--json``, ``--quiet``, old spellings as hidden aliases,
British spellings accepted), live in :mod:`semmatch.cli.common`. ``semmatch bench <what>``
benchmarks are registered the same way by modules under :mod:`semmatch.cli.bench`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from semmatch.cli.common import (
    LONG_VERBS,
    Parser,
    accept_british_spellings,
    add_quiet,
    add_sequence,
    emit,
    number,
    sequence_arg,
)

__all__ = ["VERBS", "LONG_VERBS", "build_parser", "main", "add_quiet", "add_sequence", "sequence_arg", "number",
           "emit"]

#: verb modules, in the order ``semmatch --help`` lists them
VERBS = ("simulate", "train", "adapt", "predict", "reconstruct", "align", "transfer", "evaluate", "panoptic", "show",
         "convert", "replay", "bench")


def build_parser() -> argparse.ArgumentParser:
    """The full ``semmatch`` argument parser."""
    parser = Parser(
        prog="semmatch",
        description="3D semantic label transfer across human and robot viewpoints.",
    )
    from semmatch import __version__

    parser.add_argument("--version", action="version", version=f"semmatch {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.required = True
    for verb in VERBS:
        importlib.import_module(f"semmatch.cli.{verb}").register(sub)
    accept_british_spellings(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``semmatch`` console script."""
    from concurrent.futures.process import BrokenProcessPool

    from semmatch.io.outputs import check_cli_paths, terminate_as_interrupt
    from semmatch.runtime.threads import configure

    try:  # threads set once, before the verbs load torch, Open3D or a BLAS (semmatch.runtime.threads)
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
