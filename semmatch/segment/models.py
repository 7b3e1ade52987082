"""Two semantic segmentation networks in plain PyTorch.

``compact``
    An LR-ASPP head (Howard et al., "Searching for MobileNetV3", ICCV 2019) on a small
    MobileNetV2-style encoder of inverted residual blocks, small enough for CPU inference at
    camera rate (`semmatch bench segment`). Stands in for the paper's Mask R-CNN.
``strong``
    A deeper residual encoder with atrous spatial pyramid pooling and a DeepLabV3+-style
    decoder (Chen et al., ECCV 2018) fed by skip connections at 1/4 and 1/2 resolution.
    Stands in for the paper's Mask Transfiner.

Both take an RGB image (optionally with a depth channel) normalised by
:func:`semmatch.segment.models.normalise_inputs` and return logits over the
:data:`semmatch.io.labels.NUM_CLASSES` categories at input resolution.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..io.labels import NUM_CLASSES

#: the ``format`` entry of a semmatch segmentation checkpoint
CHECKPOINT_FORMAT = "semmatch-segment/1"

__all__ = ["CHECKPOINT_FORMAT", "ARCHITECTURES", "ModelConfig", "read_checkpoint", "build_network", "normalise_inputs", "CompactNet", "StrongNet", "count_parameters"]

#: largest network input side a configuration may ask for (the views are 640x480 at most)
MAX_INPUT_SIDE = 4096
#: largest number of output classes a configuration may ask for
MAX_CLASSES = 1024

#: depth values are divided by this (metres) and clipped to [0, 2]
DEPTH_NORM = 4.0


@dataclass(frozen=True)
class ModelConfig:
    """Architecture of a segmentation network (stored in every checkpoint).

    Parameters
    ----------
    arch : {"compact", "strong"}
    use_depth : bool
        Add the metric depth as a fourth input channel.
    width, height : int
        Resolution the network runs at; other image sizes are resized in and the
        probabilities restored to the input size.
    num_classes : int
        Output channels, one per category of :mod:`semmatch.io.labels`.
    """

    arch: str = "compact"
    use_depth: bool = False
    width: int = 160
    height: int = 120
    num_classes: int = NUM_CLASSES

    def __post_init__(self) -> None:
        # checked before any network is built: a checkpoint's configuration is data, not trusted
        if not isinstance(self.arch, str) or self.arch not in ARCHITECTURES:
            raise ValueError(f"unknown architecture {self.arch!r}; choose one of {', '.join(ARCHITECTURES)}")
        if not isinstance(self.use_depth, bool):
            raise ValueError(f"use_depth must be true or false, got {self.use_depth!r}")
        for name in ("width", "height", "num_classes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer):
                raise ValueError(f"{name} must be an integer, got {v!r}")
        if not (16 <= self.width <= MAX_INPUT_SIDE and 16 <= self.height <= MAX_INPUT_SIDE):
            raise ValueError(f"network input must be 16..{MAX_INPUT_SIDE} pixels a side, got {self.width}x{self.height}")
        if not 2 <= self.num_classes <= MAX_CLASSES:
            raise ValueError(f"num_classes must be 2..{MAX_CLASSES}, got {self.num_classes}")

    @property
    def in_channels(self) -> int:
        """3 (RGB) or 4 (RGB + depth)."""
        return 4 if self.use_depth else 3

    def to_dict(self) -> dict:
        """Plain dictionary (JSON and ``torch.load(weights_only=True)`` friendly)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown model config keys: {', '.join(sorted(unknown))}")
        return cls(**d)


def read_checkpoint(path) -> dict:
    """Load a checkpoint file with ``torch.load(weights_only=True)``: data only, never code.

    Parameters
    ----------
    path : path
        An existing file.

    Returns
    -------
    object
        What the file holds (tensors, dictionaries, lists, numbers, strings).

    Raises
    ------
    ValueError
        A corrupt file, or a pickle of other Python objects (which could run code when loaded).
    """
    import pickle

    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        detail = next((lines[i + 1] for i, ln in enumerate(lines[:-1]) if "WeightsUnpickler error" in ln),
                      lines[0][:200] if lines else "")
        raise ValueError(f"{path}: not loadable as a weights-only checkpoint ({detail}): a corrupt file, or a "
                         "pickle of other Python objects, which semmatch refuses to load (it could run code)") from None
    except Exception as e:  # torch raises many types for a corrupt file
        first = (str(e).strip().splitlines() or [""])[0][:200]
        raise ValueError(f"{path}: not a readable PyTorch checkpoint ({type(e).__name__}: {first})") from None


def normalise_inputs(rgb: torch.Tensor, depth: torch.Tensor | None) -> torch.Tensor:
    """Stack network inputs: ``rgb`` float in [0, 1] (B,3,H,W), ``depth`` metres (B,1,H,W) or None.

    RGB is centred on 0 (``x - 0.5``); depth is divided by :data:`DEPTH_NORM` and clipped to
    [0, 2] (0 = no measurement). The result is channels-last in memory, the layout the networks
    run in (their depthwise convolutions are faster so on CPU).
    """
    x = rgb - 0.5
    if depth is not None:
        x = torch.cat([x, torch.clamp(depth / DEPTH_NORM, 0.0, 2.0)], dim=1)
    return x.contiguous(memory_format=torch.channels_last)


def _conv_bn(cin: int, cout: int, k: int = 3, stride: int = 1, dilation: int = 1, groups: int = 1,
             act: bool = True) -> nn.Sequential:
    pad = dilation * (k // 2)
    layers: list[nn.Module] = [
        nn.Conv2d(cin, cout, k, stride, pad, dilation=dilation, groups=groups, bias=False),
        nn.BatchNorm2d(cout),
    ]
    if act:
        layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class InvertedResidual(nn.Module):
    """MobileNetV2 block: 1x1 expand, 3x3 depthwise, 1x1 project (+ identity when shapes match)."""

    def __init__(self, cin: int, cout: int, stride: int, expand: int = 4) -> None:
        super().__init__()
        mid = cin * expand
        self.block = nn.Sequential(
            _conv_bn(cin, mid, 1),
            _conv_bn(mid, mid, 3, stride, groups=mid),
            _conv_bn(mid, cout, 1, act=False),
        )
        self.residual = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.block(x)
        return x + y if self.residual else y


class BasicBlock(nn.Module):
    """ResNet basic block with optional dilation."""

    def __init__(self, cin: int, cout: int, stride: int = 1, dilation: int = 1) -> None:
        super().__init__()
        self.conv1 = _conv_bn(cin, cout, 3, stride, dilation)
        self.conv2 = _conv_bn(cout, cout, 3, 1, dilation, act=False)
        self.down = None
        if stride != 1 or cin != cout:
            self.down = _conv_bn(cin, cout, 1, stride, act=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        idt = x if self.down is None else self.down(x)
        return F.relu(idt + self.conv2(self.conv1(x)), inplace=True)


def _up(x: torch.Tensor, ref: torch.Tensor | tuple[int, int]) -> torch.Tensor:
    size = ref if isinstance(ref, tuple) else ref.shape[-2:]
    return F.interpolate(x, size=size, mode="bilinear", align_corners=False)


class CompactNet(nn.Module):
    """LR-ASPP segmentation head on a small inverted-residual encoder (~0.14 M parameters)."""

    def __init__(self, in_channels: int = 3, num_classes: int = NUM_CLASSES) -> None:
        super().__init__()
        self.stem = _conv_bn(in_channels, 16, 3, 2)                      # 1/2
        self.stage1 = nn.Sequential(InvertedResidual(16, 24, 2), InvertedResidual(24, 24, 1))  # 1/4
        self.stage2 = nn.Sequential(InvertedResidual(24, 40, 2), InvertedResidual(40, 40, 1))  # 1/8
        self.stage3 = nn.Sequential(                                      # 1/16
            InvertedResidual(40, 64, 2), InvertedResidual(64, 64, 1), InvertedResidual(64, 64, 1)
        )
        self.cbr = _conv_bn(64, 96, 1)
        self.scale = nn.Sequential(nn.AdaptiveAvgPool2d(1), nn.Conv2d(64, 96, 1), nn.Sigmoid())
        self.high_cls = nn.Conv2d(96, num_classes, 1)
        self.low_cls = nn.Conv2d(24, num_classes, 1)
        self.fine_cls = nn.Conv2d(16, num_classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        size = x.shape[-2:]
        s0 = self.stem(x)
        s1 = self.stage1(s0)
        s3 = self.stage3(self.stage2(s1))
        y = self.cbr(s3) * self.scale(s3)
        y = self.high_cls(_up(y, s1)) + self.low_cls(s1)
        y = _up(y, s0) + self.fine_cls(s0)
        return _up(y, tuple(size))


class ASPP(nn.Module):
    """Atrous spatial pyramid pooling: 1x1, three dilated 3x3 branches and image pooling."""

    def __init__(self, cin: int, cout: int, rates: tuple[int, ...] = (2, 4, 6)) -> None:
        super().__init__()
        self.branches = nn.ModuleList([_conv_bn(cin, cout, 1)] + [_conv_bn(cin, cout, 3, dilation=r) for r in rates])
        self.pool = nn.Sequential(nn.AdaptiveAvgPool2d(1), nn.Conv2d(cin, cout, 1), nn.ReLU(inplace=True))
        self.project = nn.Sequential(_conv_bn(cout * (len(rates) + 2), cout, 1), nn.Dropout2d(0.1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        feats = [b(x) for b in self.branches]
        feats.append(self.pool(x).expand(-1, -1, x.shape[-2], x.shape[-1]))
        return self.project(torch.cat(feats, dim=1))


class StrongNet(nn.Module):
    """Residual encoder + ASPP + DeepLabV3+-style decoder with 1/4 and 1/2 skips (~2.7 M parameters)."""

    def __init__(self, in_channels: int = 3, num_classes: int = NUM_CLASSES) -> None:
        super().__init__()
        self.stem = nn.Sequential(_conv_bn(in_channels, 32, 3, 2), _conv_bn(32, 32, 3))   # 1/2
        self.layer1 = nn.Sequential(BasicBlock(32, 48, 2), BasicBlock(48, 48))          # 1/4
        self.layer2 = nn.Sequential(BasicBlock(48, 96, 2), BasicBlock(96, 96))          # 1/8
        self.layer3 = nn.Sequential(BasicBlock(96, 160, 2), BasicBlock(160, 160),       # 1/16
                                    BasicBlock(160, 160, dilation=2))
        self.aspp = ASPP(160, 128)
        self.skip1 = _conv_bn(48, 48, 1)
        self.dec1 = nn.Sequential(_conv_bn(128 + 48, 96, 3), _conv_bn(96, 96, 3))
        self.skip0 = _conv_bn(32, 24, 1)
        self.dec0 = _conv_bn(96 + 24, 64, 3)
        self.cls = nn.Conv2d(64, num_classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        size = x.shape[-2:]
        s0 = self.stem(x)
        s1 = self.layer1(s0)
        y = self.aspp(self.layer3(self.layer2(s1)))
        y = self.dec1(torch.cat([_up(y, s1), self.skip1(s1)], dim=1))
        y = self.dec0(torch.cat([_up(y, s0), self.skip0(s0)], dim=1))
        return _up(self.cls(y), tuple(size))


ARCHITECTURES: dict[str, type[nn.Module]] = {"compact": CompactNet, "strong": StrongNet}


def build_network(config: ModelConfig) -> nn.Module:
    """Instantiate the (untrained) network described by ``config``."""
    return ARCHITECTURES[config.arch](config.in_channels, config.num_classes)


def count_parameters(net: nn.Module) -> int:
    """Number of trainable parameters."""
    return int(sum(int(np.prod(p.shape)) for p in net.parameters() if p.requires_grad))
