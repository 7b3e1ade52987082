"""``python -m semmatch.experiments``: run notebooks with a profile of ``params.yaml``."""

import sys

from semmatch.experiments.pipeline import main

sys.exit(main())
