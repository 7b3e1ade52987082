"""Evaluation: the benchmark measures, the independent reference and the statistics over scenes.

The pipeline's last step: :mod:`~semmatch.evaluate.metrics` computes the paper's measures on
semantic voxel grids (and the 2D pixel measures of segmentations);
:mod:`~semmatch.evaluate.reference` builds an evaluation reference that shares nothing with a
prediction but the surfaces the camera saw (the ground-truth mesh sampled where it was
observed); :mod:`~semmatch.evaluate.stats` gives the intervals over scenes and the tests behind
the claims' verdicts.

Import the names from their submodules (``from semmatch.evaluate.metrics import compare``): the
package itself imports nothing, so a stage that uses one of them does not depend on the others.
"""
