"""``semmatch bench {render,transfer,fusion,metrics,segment,train,online} [--json]``.

Each benchmark lives in ``semmatch/cli/bench/<what>.py`` with ``register(subparsers)``; it
prints a human table, or one JSON object with ``--json`` (:func:`semmatch.cli.common.add_json`,
:func:`semmatch.cli.common.emit`).
"""

from __future__ import annotations

import importlib
import json
import sys

WHATS = ("render", "transfer", "fusion", "metrics", "segment", "train", "online")


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


#: the environments of ``--thread-rows``: (row label, thread variables set; the others removed)
THREAD_ROWS = (
    ("default environment", {}),
    ("OMP_NUM_THREADS=1", {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}),
    ("no limit (SEMMATCH_THREADS=0)", {"SEMMATCH_THREADS": "0"}),
)


def add_thread_flags(parser, what: str) -> None:
    """``--threads N`` and ``--thread-rows`` of a benchmark that runs torch / Open3D / BLAS code."""
    from semmatch.cli.common import number

    parser.add_argument("--threads", type=number(int, lo=0), default=None,
                        help="CPU threads of torch, Open3D, OpenMP and the BLAS; 0: the libraries' own (default: "
                             "semmatch's setting, SEMMATCH_THREADS, else 1; semmatch.runtime.threads)")
    parser.add_argument("--thread-rows", action="store_true",
                        help=f"run this {what} benchmark in fresh processes with no thread variable set (semmatch's "
                             "own setting), with OMP_NUM_THREADS=1, and with no limit (SEMMATCH_THREADS=0: the "
                             "libraries' own), and print one row each")
    parser.set_defaults(_bench_parser=parser)


def apply_threads(args) -> dict:
    """Set ``args.threads`` (when given) through :func:`semmatch.runtime.threads.configure`; the limits now in force."""
    from semmatch.runtime.threads import configure, current

    if args.threads is not None:
        if args.threads < 0:
            raise ValueError(f"--threads must be >= 0, got {args.threads}")
        configure("cli", n=args.threads)
    return current()


def _argv_of(args) -> list[str]:
    """The options of ``args`` that differ from their defaults, as command-line words in their
    canonical spelling (without ``--json``, ``--threads`` and ``--thread-rows``)."""
    import argparse

    from semmatch.cli.common import ImageSize

    out: list[str] = []
    for action in args._bench_parser._actions:
        dest, flags = action.dest, [f for f in action.option_strings if f.startswith("--")]
        if not flags or dest in ("help", "json", "threads", "thread_rows") or action.help == argparse.SUPPRESS:
            continue  # hidden old spellings: their values are the canonical option's
        value = getattr(args, dest, action.default)
        if value == action.default:
            continue
        if action.nargs == 0:  # store_true / store_false
            out.append(flags[0])
        elif isinstance(value, ImageSize):
            out += [flags[0], str(value)]
        elif isinstance(value, list | tuple):
            out += [flags[0], *map(str, value)]
        else:
            out += [flags[0], str(value)]
    return out


def thread_rows(args, what: str, timeout_s: float = 1800) -> list[dict]:
    """Run ``semmatch bench <what>`` with the options of ``args`` once per :data:`THREAD_ROWS`
    environment, each in a fresh process (thread variables are read when libraries load).

    Returns
    -------
    list of dict
        Per environment: ``row`` (its label), ``env`` (the variables set) and the benchmark's JSON.
    """
    import os
    import subprocess

    from semmatch.runtime.threads import ENV_VARS, THREADS_ENV

    code = "import sys; from semmatch.cli import main; sys.exit(main(sys.argv[1:]))"
    cmd = [sys.executable, "-c", code, "bench", what, "--json", *_argv_of(args)]
    rows = []
    for label, extra in THREAD_ROWS:
        env = {k: v for k, v in os.environ.items() if k not in (THREADS_ENV, *ENV_VARS)}
        env.update(extra)
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
        if done.returncode != 0:
            raise ValueError(f"semmatch bench {what} with {label} failed (exit {done.returncode}): "
                             f"{done.stderr.strip()[-400:]}")
        rows.append({"row": label, "env": extra, **json.loads(done.stdout.strip().splitlines()[-1])})
    return rows
