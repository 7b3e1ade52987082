"""One interface over the transfer methods: ``transfer(name, frame, map_or_index, **params)``."""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from ..io import Frame, SemanticMap
from . import methods as _m
from .frames import check_frame
from .fused import fuse_with_probabilities
from .index import MapIndex, as_map_index

__all__ = [
    "METHODS", "ALL_METHODS", "PAPER_FPS", "TransferResult", "transfer", "transfer_frame",
    "method_params", "check_params", "settings_for", "register_method", "available_methods", "method_info", "MethodInfo",
]


@dataclass(frozen=True)
class MethodInfo:
    """A registered transfer method.

    Attributes
    ----------
    name : str
    fn : callable
        ``fn(fd: FrameData, index: MapIndex, *, <keyword-only parameters>) -> (labels, purity,
        groups)`` (see :mod:`semmatch.transfer.methods`).
    needs_rgb : bool
        Whether the method reads the frame's colours (``dbscan`` and ``3d-neighborhood`` do not).
    paper_fps : float or None
        The paper's Table 1 speed, shown beside ours by ``semmatch bench transfer``.
    """

    name: str
    fn: Callable
    needs_rgb: bool = True
    paper_fps: float | None = None


_REGISTRY: dict[str, MethodInfo] = {}


def register_method(
    name: str, fn: Callable, *, needs_rgb: bool = True, paper_fps: float | None = None, replace: bool = False
) -> MethodInfo:
    """Add a transfer method: the one way to do it.

    A registered method is called by :func:`transfer` / :func:`transfer_frame` /
    :func:`~semmatch.transfer.transfer_sequence`, offered by ``semmatch transfer --method`` and
    ``semmatch panoptic transfer --method``, timed by ``semmatch bench transfer --methods`` and
    run by the notebooks when listed in ``params.yaml`` (``methods``). Its keyword-only
    parameters (with defaults) become its parameters (:func:`method_params`, ``--param
    KEY=VALUE``). Packages register methods for the command line through the entry-point group
    ``semmatch.transfer_methods`` (a callable that calls this function).

    Parameters
    ----------
    name : str
        Method name (not ``fused``, which combines a method with a network).
    fn : callable
        ``fn(fd, index, **params) -> (labels uint8 (H,W), purity float32 (H,W), groups int64
        (H,W) or None)``: ``fd`` a validated :class:`~semmatch.transfer.frames.FrameData`,
        ``index`` the upper map's :class:`~semmatch.transfer.index.MapIndex`; labels 0 where
        the map gives no support; ``groups`` the pixel grouping (None for per-pixel methods).
    needs_rgb, paper_fps
        See :class:`MethodInfo`.
    replace : bool
        Allow replacing a registered method of the same name.

    Returns
    -------
    MethodInfo

    Raises
    ------
    ValueError
        A reserved or taken name, or ``fn`` not taking ``(fd, index, *, ...)``.
    """
    if not isinstance(name, str) or not name or name == "fused":
        raise ValueError(f"invalid transfer method name {name!r} ('fused' is reserved)")
    if name in _REGISTRY and not replace:
        raise ValueError(f"transfer method {name!r} is already registered (pass replace=True to replace it)")
    if not callable(fn):
        raise ValueError(f"{name}: fn must be callable, got {type(fn).__name__}")
    params = list(inspect.signature(fn).parameters.values())
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if len(positional) != 2 or params[:2] != positional:
        raise ValueError(f"{name}: fn must be fn(fd, index, *, param=default, ...): two positional "
                         "parameters, then keyword-only ones")
    info = MethodInfo(name, fn, bool(needs_rgb), None if paper_fps is None else float(paper_fps))
    _REGISTRY[name] = info
    return info


def available_methods() -> tuple[str, ...]:
    """Every registered method (the paper's five first), then ``fused``."""
    return tuple(_REGISTRY) + ("fused",)


def method_info(name: str) -> MethodInfo:
    """The :class:`MethodInfo` of a registered method (``ValueError`` naming the valid ones)."""
    _check_name(name)
    return _REGISTRY[name]


for _name, _fn, _rgb, _fps in (  # the paper's methods, in the order of its Table 1, with its speeds
    ("2d-slic", _m.slic_2d, True, 2.29),
    ("3d-slic", _m.slic_3d, True, 1.04),
    ("3d-projected-sp", _m.projected_sp_3d, True, 9.57),
    ("dbscan", _m.dbscan, False, 0.84),
    ("3d-neighborhood", _m.neighborhood_3d, False, 20.06),
):
    register_method(_name, _fn, needs_rgb=_rgb, paper_fps=_fps)

#: The paper's five methods (the paper, §3), in the order of its Table 1.
METHODS: tuple[str, ...] = tuple(_REGISTRY)

#: The paper's methods plus ``fused`` (transfer + a network's probabilities). Every registered
#: method, plugins included: :func:`available_methods`.
ALL_METHODS: tuple[str, ...] = METHODS + ("fused",)

#: Paper Table 1 (FPS on an AMD EPYC 7401P server).
PAPER_FPS: dict[str, float] = {k: v.paper_fps for k, v in _REGISTRY.items()}


def _load_plugins() -> None:
    """Run the ``semmatch.transfer_methods`` entry points (packages registering methods)."""
    import warnings
    from importlib.metadata import entry_points

    for ep in entry_points(group="semmatch.transfer_methods"):
        try:
            ep.load()()
        except Exception as e:  # noqa: BLE001 - a broken plugin must not break semmatch
            warnings.warn(f"transfer-method plugin {ep.name!r} ({ep.value}) failed to load: {e}", stacklevel=2)


_load_plugins()


@dataclass
class TransferResult:
    """Labels of one frame with its statistics.

    Attributes
    ----------
    labels : uint8 (H,W)
        Category ids, 0 = no support in the map.
    coverage : float
        Share of the pixels with depth that got a label (0 when no pixel has depth).
    seconds : float
        Wall time of the method on this frame (indexing the map excluded).
    purity : float32 (H,W)
        Share of the pixel's group votes that agreed with its label (1 for ``3d-neighborhood``,
        0 for void pixels).
    method : str
    groups : int64 (H,W) or None
        The method's grouping of the pixels (superpixel, supervoxel or cluster id; -1 = in no
        group); None for per-pixel methods (``3d-neighborhood``). Panoptic transfer gives each
        group one instance.
    """

    labels: np.ndarray
    coverage: float
    seconds: float
    purity: np.ndarray
    method: str
    groups: np.ndarray | None = None


def method_params(name: str) -> dict:
    """Parameters of method ``name`` and their defaults (``max_distance`` included)."""
    if name == "fused":
        return {"probs": None, "base": "3d-projected-sp", "min_purity": 0.5, "max_distance": None}
    fn = _check_name(name)
    sig = inspect.signature(fn)
    out = {k: p.default for k, p in list(sig.parameters.items())[2:] if p.kind == p.KEYWORD_ONLY}
    out["max_distance"] = None
    return out


def _check_name(name: str) -> Callable:
    if name not in _REGISTRY:
        raise ValueError(f"unknown transfer method {name!r}; valid: {', '.join(available_methods())}")
    return _REGISTRY[name].fn


def check_params(name: str, params: dict) -> None:
    """Raise ``ValueError`` naming the valid parameters when ``params`` has unknown keys."""
    valid = method_params(name)
    if name == "fused":
        base = params.get("base", "3d-projected-sp")
        if base in _REGISTRY:
            valid = {**valid, **method_params(base)}
    bad = sorted(set(params) - set(valid))
    if bad:
        raise ValueError(f"{name}: unknown parameter(s) {', '.join(bad)}; valid: {', '.join(valid)}")


def settings_for(name: str, settings: Mapping[str, Mapping] | None) -> dict:
    """The parameters of method ``name`` in a per-method settings mapping, checked.

    A run states the settings of its methods once, as ``{method: {parameter: value}}`` (e.g. the
    analysis plan v2's ``2d-slic`` lever, ``{"2d-slic": {"iterations": 3}}`` from params.yaml's
    ``slic_2d``); every study passes ``settings_for(method, settings)`` on to the method.

    Parameters
    ----------
    name : str
        A method (:func:`available_methods`).
    settings : mapping or None
        ``{method: {parameter: value}}``; methods it does not name keep their defaults.

    Returns
    -------
    dict
        A copy of ``settings[name]`` (empty when absent).

    Raises
    ------
    ValueError
        An unknown method in ``settings`` or an unknown parameter of ``name``.
    """
    settings = dict(settings or {})
    unknown = sorted(set(settings) - set(available_methods()))
    if unknown:
        raise ValueError(f"method settings name unknown method(s) {', '.join(unknown)}; "
                         f"valid: {', '.join(available_methods())}")
    own = settings.get(name)
    if own is not None and not isinstance(own, Mapping):
        raise ValueError(f"method settings of {name}: expected a mapping of parameters, got {own!r}")
    out = dict(own or {})
    check_params(name, out)
    return out


def _call(name: str, fd, index: MapIndex, params: dict):
    check_params(name, params)
    return _check_name(name)(fd, index, **params)


def transfer_frame(
    name: str,
    frame: Frame,
    semantic_map: SemanticMap | MapIndex,
    *,
    max_distance: float | None = None,
    **params,
) -> TransferResult:
    """Transfer the labels of an upper map into one lower frame, with statistics.

    Parameters
    ----------
    name : str
        A registered method (:func:`available_methods`: the paper's five, ``fused`` and any
        added with :func:`register_method`).
    frame : Frame
        RGB (not needed by ``dbscan``/``3d-neighborhood``), metric depth, pose, intrinsics.
    semantic_map : SemanticMap or MapIndex
        The upper map, or its prebuilt :class:`MapIndex` (``as_map_index(map)``) to index it once
        for a whole sequence.
    max_distance : float, optional
        Distance threshold (metres) beyond which a pixel's 3D point has no support (label 0);
        default :data:`~semmatch.transfer.index.DEFAULT_MAX_DISTANCE` (0.10 m) or the index's.
    **params
        Method parameters (:func:`method_params`). ``fused`` takes ``probs`` (H,W,C) (or reads
        ``frame.extras["probs"]``), ``base`` (a method name, default ``3d-projected-sp``),
        ``min_purity`` and the base method's parameters.

    Returns
    -------
    TransferResult

    Raises
    ------
    ValueError
        Unknown method or parameter, bad frame (size, pose), empty map, index built for
        another ``max_distance``.
    """
    if name != "fused":
        _check_name(name)
    check_params(name, {"max_distance": max_distance, **params})
    index = as_map_index(semantic_map, max_distance=max_distance)
    t1 = time.perf_counter()
    if name == "fused":
        probs = params.pop("probs", None)
        if probs is None:
            probs = getattr(frame, "extras", {}).get("probs")
        if probs is None:
            raise ValueError("fused needs probs=(H,W,C) class probabilities (or frame.extras['probs'])")
        base = params.pop("base", "3d-projected-sp")
        min_purity = params.pop("min_purity", 0.5)
        if base == "fused" or base not in _REGISTRY:
            raise ValueError(f"fused: base must be one of {', '.join(_REGISTRY)}, got {base!r}")
        fd = check_frame(frame, need_rgb=_REGISTRY[base].needs_rgb)
        labels, purity, groups = _call(base, fd, index, params)
        labels = fuse_with_probabilities(labels, probs, purity=purity, min_purity=min_purity)
        purity = np.where(labels == 0, 0, purity).astype(np.float32)
    else:
        fd = check_frame(frame, need_rgb=_REGISTRY[name].needs_rgb)
        labels, purity, groups = _call(name, fd, index, params)
    seconds = time.perf_counter() - t1
    n_valid = fd.n_valid
    # the paper's methods leave pixels without depth at 0; fused may label them from the network
    n_lab = np.count_nonzero(labels[fd.valid]) if name == "fused" else np.count_nonzero(labels)
    coverage = float(n_lab / n_valid) if n_valid else 0.0
    return TransferResult(labels, coverage, seconds, purity, name, groups)


def transfer(
    name: str, frame: Frame, semantic_map: SemanticMap | MapIndex, **params
) -> np.ndarray:
    """Transfer labels into one frame: ``(H,W) uint8``, 0 = no support in the map.

    Same arguments as :func:`transfer_frame`, which also returns coverage and time.

    Examples
    --------
    >>> from semmatch.io import read_map, read_sequence        # doctest: +SKIP
    >>> m, seq = read_map("upper.ply"), read_sequence("lower")  # doctest: +SKIP
    >>> lab = transfer("3d-neighborhood", seq[0], m)            # doctest: +SKIP
    """
    return transfer_frame(name, frame, semantic_map, **params).labels
