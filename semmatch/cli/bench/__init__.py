"""``semmatch bench {render,transfer,fusion,metrics,segment,train} [--json]``.

Each benchmark lives in ``semmatch/cli/bench/<what>.py`` with ``register(subparsers)``; it
prints a human table, or one JSON object with ``--json``.
"""

from __future__ import annotations

import importlib
import json
import sys

WHATS = ("render", "transfer", "fusion", "metrics", "segment", "train")


def register(sub) -> None:
    """Add ``semmatch bench`` and its benchmarks."""
    p = sub.add_parser("bench", help="benchmarks that print numbers (--json: one JSON object)")
    bsub = p.add_subparsers(dest="what", metavar="WHAT")
    bsub.required = True
    for what in WHATS:
        try:
            mod = importlib.import_module(f"semmatch.cli.bench.{what}")
        except ModuleNotFoundError as e:
            if e.name == f"semmatch.cli.bench.{what}":
                continue
            raise
        mod.register(bsub)


def add_json_flag(parser) -> None:
    """The shared ``--json`` flag."""
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def emit(result: dict, as_json: bool, table: str) -> int:
    """Print ``result`` as JSON or ``table`` as text; return 0."""
    if as_json:
        json.dump(result, sys.stdout)
        sys.stdout.write("\n")
    else:
        print(table)
    return 0
