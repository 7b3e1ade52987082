"""``python -m semmatch.experiments``: run notebooks with a profile of ``params.yaml``; ``confirm``, ``ship`` and ``rejudge``."""

import sys

from semmatch.experiments.confirm import add_confirm_parser, add_ship_adapted_parser, add_ship_parser
from semmatch.experiments.pipeline import main
from semmatch.experiments.rejudge import add_rejudge_parser

sys.exit(main(extra_commands=(add_confirm_parser, add_ship_parser, add_ship_adapted_parser, add_rejudge_parser)))
