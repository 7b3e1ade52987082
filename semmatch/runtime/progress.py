"""Progress bars that suit where semmatch runs: widgets in Jupyter, a terminal bar in a shell,
plain text lines under papermill / DVC.

Every long loop of semmatch uses :func:`tqdm` from here. ``tqdm.auto`` picks a Jupyter widget
in any kernel, which is right in JupyterLab but leaves bars frozen at 0 % in notebooks executed
by papermill (the pipeline). With ``SEMMATCH_PROGRESS=text`` in the environment (set by
:func:`semmatch.experiments.pipeline.run_notebook` for the kernels it starts) bars are plain
text, refreshed at most every ``SEMMATCH_PROGRESS_INTERVAL`` seconds (default 30), so an executed
report holds a few readable progress lines per loop instead of a widget.
"""

from __future__ import annotations

import os

__all__ = ["tqdm", "text_mode"]


def text_mode() -> bool:
    """True when progress should be plain text lines (``SEMMATCH_PROGRESS=text``)."""
    return os.environ.get("SEMMATCH_PROGRESS", "").lower() == "text"


def tqdm(*args, **kwargs):
    """``tqdm.auto.tqdm``, or a plain-text ``tqdm`` refreshed rarely in text mode."""
    if text_mode():
        from tqdm.std import tqdm as text_tqdm

        kwargs.setdefault("mininterval", float(os.environ.get("SEMMATCH_PROGRESS_INTERVAL", "30")))
        kwargs.setdefault("ascii", True)
        kwargs.setdefault("dynamic_ncols", False)
        kwargs.setdefault("ncols", 100)
        return text_tqdm(*args, **kwargs)
    from tqdm.auto import tqdm as auto_tqdm

    return auto_tqdm(*args, **kwargs)
