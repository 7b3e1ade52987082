"""Camera poses: estimating them for recordings without ground truth, and measuring them.

The pipeline's first step for a real recording, before fusion: frame-to-frame RGB-D odometry
that gives the same result on every run (:mod:`~semmatch.poses.rgbd_odometry`), chained and
refined by a pose graph (:mod:`~semmatch.poses.pose_graph`) into a trajectory
(:mod:`~semmatch.poses.odometry`; the pipeline's chain that runs it on a whole recording is
:func:`semmatch.experiments.real.evaluate_real_like`); the
registration of two reconstructions of one room from geometry alone
(:mod:`~semmatch.poses.registration`); and trajectory errors against ground truth, ATE and RPE
(:mod:`~semmatch.poses.trajectory_metrics`).

Import the names from their submodules (``from semmatch.poses.odometry import
estimate_poses``): the package itself imports nothing, so a stage that uses one of them does
not depend on the others.
"""
