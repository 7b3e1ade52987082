"""Semantic segmentation: two trained networks, a (noisy) ground-truth oracle, a detectron2 adapter
and the viewpoint-gap study.

Public surface::

    from semmatch.segment import load_model
    net = load_model(checkpoint); probs = net.predict(rgb)  # (H,W,21) float32, sums to 1

Submodules: :mod:`~semmatch.segment.models` (architectures), :mod:`~semmatch.segment.data`
(rendered views), :mod:`~semmatch.segment.training`, :mod:`~semmatch.segment.predict`,
:mod:`~semmatch.segment.oracle`, :mod:`~semmatch.segment.detectron2`,
:mod:`~semmatch.segment.viewpoint`, and :mod:`~semmatch.segment.adapt` (fine-tuning a network
to the robot's viewpoint with transferred labels; imported from there). Names are imported
lazily so that ``import semmatch.segment`` does not import PyTorch.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "load_model": "predict",
    "predict_sequence": "predict",
    "Segmenter": "predict",
    "train": "training",
    "make_config": "train_config",
    "network_spec": "train_config",
    "pipeline_configs": "train_config",
    "TrainConfig": "train_config",
    "PROFILES": "train_config",
    "ModelConfig": "models",
    "ARCHITECTURES": "models",
    "OracleSegmenter": "oracle",
    "NoisyOracle": "oracle",
    "noisy_labels": "oracle",
    "viewpoint_gap": "viewpoint",
    "training_histories": "predict",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
