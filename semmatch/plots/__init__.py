"""Every matplotlib figure of semmatch, in one place.

The functions here draw what they are given (images, frames, tables, training histories) and
write the figure atomically (:func:`semmatch.io.save_figure`); reading files, rendering maps and
computing statistics stay in the modules that own them, which hand the results over (e.g.
:func:`semmatch.experiments.qualitative.qualitative_figure` renders the maps and calls
:func:`image_grid`). :mod:`~semmatch.plots.images` holds grids of images and floor plans,
:mod:`~semmatch.plots.charts` curves, bars and matrices. Interactive 3D views (Plotly, for
JupyterLab and HTML pages) are :mod:`~semmatch.plots.views`, imported from there: they are
shown, never written as figure files.
"""

from .charts import (
    confusion_figure,
    plot_depth_noise,
    plot_height_study,
    plot_measure_bars,
    plot_misregistration,
    plot_panoptic,
    plot_per_scene_change,
    plot_speed,
    plot_support,
    plot_table,
    plot_training_curves,
)
from .images import floor_plans_figure, frame_figure, image_grid

__all__ = [
    "confusion_figure", "plot_depth_noise", "plot_height_study", "plot_measure_bars", "plot_misregistration", "plot_panoptic", "plot_per_scene_change", "plot_speed", "plot_support",
    "plot_table", "plot_training_curves", "floor_plans_figure", "frame_figure", "image_grid",
]
