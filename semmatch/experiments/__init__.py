"""The functions the notebooks call: one call per table or figure of the paper.

:mod:`~semmatch.experiments.pipeline` runs the notebooks (papermill, profiles of
``params.yaml``); :mod:`~semmatch.experiments.paper` holds the paper's reference numbers.
"""

from .pipeline import NOTEBOOKS, load_params, notebook_parameters, notebook_setup, run_all, run_notebook

__all__ = ["NOTEBOOKS", "load_params", "notebook_parameters", "notebook_setup", "run_notebook", "run_all"]
