"""The analysis plan applied to the development scenes' committed per-scene tables (exploratory).

``python scripts/plan_on_development.py [--figures figures/full] [--out figures/development_plan]``

Reads the per-scene CSVs of the full profile's run on the development scenes (seeds 7001-7003)
and writes the plan's comparisons and verdicts (:func:`semmatch.experiments.claims.judge_figures`)
into ``--out``. These scenes were looked at during development: the output shows how the plan's
rules read on them, and decides nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from semmatch.experiments.claims import judge_figures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figures", type=Path, default=Path("figures/full"))
    ap.add_argument("--out", type=Path, default=Path("figures/development_plan"))
    args = ap.parse_args()
    table = judge_figures(args.figures, args.out)
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
