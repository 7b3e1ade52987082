"""The robot learns: adapt a segmentation network to the robot's viewpoint with transferred labels.

The paper ends where this begins ("label transfer and the fine-tuning of semantic segmentation
networks to these perspectives becomes possible"). On **training scenes only**, the person
(1.6 m) and the robot (0.2 m) each tour the room; the network builds the person's semantic map,
its labels are transferred into the robot's frames, and the network is fine-tuned on those
frames (:func:`fine_tune`). Label sources (:data:`LABEL_SOURCES`):

* a transfer method (the paper's five): its labels where the map supports a pixel and the
  pixel's group agreed (vote purity >= ``min_purity``); everything else is ignored by the loss;
* ``fused``: the transferred label where the map supports a pixel, the network's elsewhere;
* ``self-training`` (the standard domain-adaptation baseline): the network's own predictions on
  the robot's frames where its confidence is >= ``self_threshold``;
* ``ground-truth`` (the ceiling): the simulator's labels of the robot's frames.

Forgetting the human view is guarded against by mixing each batch: ``upper_share`` of it comes
from the network's own human-height training views with their ground truth.
The adapted checkpoint records what it was adapted from and with (``adapted``); it loads with
:func:`semmatch.segment.load_model` like any other.

Submodules: :mod:`~semmatch.segment.adapt.views` (the robot's frames and their labels of every
source) and :mod:`~semmatch.segment.adapt.finetune` (the recipe and the fine-tuning); every public
name is importable from ``semmatch.segment.adapt`` itself.
"""

from .finetune import AdaptRecipe, adapt_in_home, fine_tune
from .views import (
    HOME_SOURCES,
    LABEL_SOURCES,
    MIN_COVERAGE,
    RobotViews,
    adapted_name,
    home_views,
    label_robot_frame,
    robot_training_views,
)

__all__ = ["LABEL_SOURCES", "HOME_SOURCES", "MIN_COVERAGE", "AdaptRecipe", "RobotViews", "label_robot_frame",
           "robot_training_views", "home_views", "adapt_in_home", "fine_tune", "adapted_name"]
