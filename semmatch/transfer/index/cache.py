"""The index of a map file, built once and cached: where the cache goes, its key, and a file that
is read only when it proves to be this map's.

A cache file holds the label grid of one map at one set of index parameters (the costly part of
an index: seconds and most of the memory for a room), keyed by the SHA-256 of the map file's
bytes, the parameters and :data:`INDEX_CACHE_VERSION`. It goes to a user cache folder by default
(:func:`index_cache_dir`): ``platformdirs.user_cache_dir("semmatch")/index``, or
``$SEMMATCH_CACHE_DIR/index``; beside the map (``.<map>.index-<key>.npz``) or into a given folder
on request. A file is used only when it is this map's (its stored map digest), its arrays hash to
the digest stored with them, and it decompresses to no more than the map's grid can hold
(checked before decompressing); otherwise the index is rebuilt with a warning and the file
rewritten.
"""

from __future__ import annotations

import hashlib
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np

from ...io import SemanticMap, atomic_path, read_map
from .label_grid import BLOCK, LabelGrid, grid_geometry, sample_bounds
from .queries import DEFAULT_MAX_DISTANCE, MapIndex

__all__ = ["load_index", "index_cache_dir", "index_cache_path", "INDEX_CACHE_VERSION", "NO_CACHE_ENV",
           "CACHE_DIR_ENV"]

#: version of the index cache files (bump when the grid's meaning changes)
INDEX_CACHE_VERSION = 3
#: environment variable that turns the index cache off (any non-empty value)
NO_CACHE_ENV = "SEMMATCH_NO_INDEX_CACHE"
#: environment variable naming semmatch's cache folder (index caches go to its ``index/``);
#: default ``platformdirs.user_cache_dir("semmatch")``
CACHE_DIR_ENV = "SEMMATCH_CACHE_DIR"


def _keyword(where, word: str) -> bool:
    return isinstance(where, str) and where == word


def index_cache_dir(map_path: str | os.PathLike, where: str | os.PathLike | None = None) -> Path:
    """The folder where the index cache of the map file ``map_path`` goes.

    Parameters
    ----------
    map_path : path
        The map file.
    where : {"user", "beside"}, path or None
        ``"user"`` or None (default): the user cache folder, ``$SEMMATCH_CACHE_DIR/index`` when
        that variable is set, else ``platformdirs.user_cache_dir("semmatch")/index``;
        ``"beside"``: the map's own folder; any other value (a ``Path``, or a string other than
        these two words): that folder.

    Returns
    -------
    Path
        The folder (not created here).

    Raises
    ------
    ValueError
        ``where`` is an empty string.
    """
    if where is None or _keyword(where, "user"):
        env = os.environ.get(CACHE_DIR_ENV)
        if env:
            return Path(env).expanduser() / "index"
        import platformdirs

        return Path(platformdirs.user_cache_dir("semmatch")) / "index"
    if _keyword(where, "beside"):
        return Path(map_path).parent
    if isinstance(where, str) and not where:
        raise ValueError('the index cache folder is an empty string: give "user", "beside" or a folder')
    return Path(where).expanduser()


def _cache_file(path: Path, max_distance: float, voxel_size: float, where) -> tuple[Path, str]:
    """The cache file of the map ``path`` and the full key: SHA-256 of its bytes and the parameters.

    Beside the map: ``.<map>.index-<key>.npz`` (hidden in the user's folder); in a cache folder:
    ``<map>.index-<key>.npz``, the key (of the map's content) keeping apart maps of one name.
    """
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    h.update(f"|{max_distance!r}|{voxel_size!r}|{INDEX_CACHE_VERSION}".encode())
    hidden = "." if _keyword(where, "beside") else ""
    name = f"{hidden}{path.name}.index-{h.hexdigest()[:16]}.npz"
    return index_cache_dir(path, where) / name, h.hexdigest()


def index_cache_path(map_path: str | os.PathLike, *, max_distance: float = DEFAULT_MAX_DISTANCE,
                     voxel_size: float = 0.02, cache_dir: str | os.PathLike | None = None) -> Path:
    """The file :func:`load_index` reads and writes for this map file and these parameters.

    Parameters
    ----------
    map_path : path
        The map file (read, to hash its bytes).
    max_distance, voxel_size, cache_dir
        As :func:`load_index`.

    Returns
    -------
    Path
    """
    return _cache_file(Path(map_path), float(max_distance), float(voxel_size), cache_dir)[0]


def _arrays_digest(data: dict) -> str:
    """SHA-256 of named arrays: names, dtypes, shapes and bytes, in name order."""
    h = hashlib.sha256()
    for k in sorted(data):
        a = np.ascontiguousarray(data[k])
        h.update(f"{k}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _read_cache(path: Path, *, limit: int) -> dict:
    """The arrays of an ``.npz`` cache; refused when they would decompress to more than ``limit`` bytes."""
    with zipfile.ZipFile(path) as zf:
        size = sum(info.file_size for info in zf.infolist())
    if size > limit:
        raise ValueError(f"it would decompress to {size:,} bytes, more than the {limit:,} the map's grid can hold")
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _read_index(semantic_map: SemanticMap, path: Path, *, map_digest: str, max_distance: float,
                voxel_size: float, workers: int = 1) -> MapIndex:
    """An index of ``semantic_map`` from its cache file (no grid build).

    The file must be the cache of this map (``map_digest``) at these parameters, its arrays
    must hash to the digest stored with them, and nothing in it may decompress to more than
    the grid the map spans can hold (checked before decompressing).
    """
    lo, hi, _ = sample_bounds(semantic_map, 0.7 * voxel_size)
    origin, shape, _ = grid_geometry(lo, hi, max_distance, voxel_size)
    nb = -(-shape // BLOCK)
    n_table = int(np.prod(nb.astype(np.float64)))
    data = _read_cache(path, limit=n_table * (4 + BLOCK**3) + 32 * len(semantic_map.points) + (1 << 20))
    if str(data.pop("map_sha256", "")) != map_digest:
        raise ValueError("it was made for another map or other parameters")
    want = str(data.pop("content_sha256", ""))
    if _arrays_digest(data) != want:
        raise ValueError("its arrays do not match their stored digest (changed after it was written)")
    if (float(data["max_distance"]) != max_distance or float(data["voxel_size"]) != float(voxel_size)
            or tuple(int(x) for x in data["shape"]) != tuple(int(x) for x in shape)
            or not np.allclose(data["origin"], origin)):
        raise ValueError("its grid is not the grid of this map")
    if not semantic_map.is_mesh and (len(data["samples"]) != len(semantic_map.points)
                                     or not np.array_equal(data["sample_labels"], semantic_map.labels)):
        raise ValueError("the cached samples do not match the map")
    table, blocks = data["table"], data["blocks"]
    if (table.shape != tuple(nb) or table.dtype != np.int32 or blocks.dtype != np.uint8
            or blocks.size % BLOCK**3 or not 0 <= table.min(initial=0) <= table.max(initial=0)
            < blocks.size // BLOCK**3):
        raise ValueError(f"block table {table.shape} / {table.dtype} and {blocks.size} block "
                         f"voxels do not fit a grid of {tuple(int(x) for x in shape)}")
    grid = LabelGrid(data["origin"].astype(np.float64), tuple(int(x) for x in data["shape"]),
                     float(data["voxel_size"]), table, blocks, int(data["n_samples"]))
    return MapIndex._from_grid(semantic_map, grid, max_distance=max_distance, workers=workers)


def _write_index(index: MapIndex, cf: Path, digest: str) -> None:
    """Write the cache file of ``index`` (atomically); a folder that cannot be written: no cache."""
    g = index.label_grid
    arrays = {"table": g.table, "blocks": g.blocks, "origin": np.asarray(g.origin), "shape": np.asarray(g.shape),
              "voxel_size": np.asarray(g.voxel_size), "max_distance": np.asarray(index.max_distance),
              "n_samples": np.asarray(g.n_samples)}
    arrays["samples"] = index.samples if index.samples is not None else np.zeros((0, 3), np.float32)
    arrays["sample_labels"] = index.sample_labels if index.sample_labels is not None else np.zeros(0, np.uint8)
    try:
        cf.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(cf) as tmp:
            np.savez_compressed(tmp, **arrays, map_sha256=np.asarray(digest),
                                content_sha256=np.asarray(_arrays_digest(arrays)))
    except OSError:  # a read-only folder: no cache
        pass
    except ValueError as e:  # a folder or special file at the cache's path (io.files.atomic_path): no cache
        warnings.warn(f"index cache not written ({e}); transferring without it", UserWarning, stacklevel=3)


def load_index(path: str | os.PathLike, *, max_distance: float = DEFAULT_MAX_DISTANCE, voxel_size: float = 0.02,
               cache: bool = True, cache_dir: str | os.PathLike | None = None,
               semantic_map: SemanticMap | None = None, **index_params) -> MapIndex:
    """The :class:`MapIndex` of a map file, built once and cached.

    The label grid is stored in a cache file keyed by the SHA-256 of the map's bytes and the
    index parameters (:func:`index_cache_path`); a later call with the same map and parameters
    loads it instead of building (the exact queries are rebuilt from the map, cheaply). A cache
    that cannot be read, or is not this map's, is rebuilt with a warning; a folder that cannot be
    written just gets no cache.

    Parameters
    ----------
    path : path
        A semantic PLY map (:func:`semmatch.io.read_map`).
    max_distance, voxel_size, **index_params
        As :class:`MapIndex`.
    cache : bool
        Use and write the cache (also off when ``SEMMATCH_NO_INDEX_CACHE`` is set).
    cache_dir : {"user", "beside"}, path or None
        Where the cache goes (:func:`index_cache_dir`): None or ``"user"`` (default) the user
        cache folder (``$SEMMATCH_CACHE_DIR/index`` when set), ``"beside"`` the map's folder
        (``.<map>.index-<key>.npz``), or a folder.
    semantic_map : SemanticMap, optional
        The map already read from ``path`` (not read again).

    Returns
    -------
    MapIndex
        Lookups identical to ``MapIndex(read_map(path), ...)``.
    """
    path = Path(path)
    m = read_map(path) if semantic_map is None else semantic_map
    if not cache or os.environ.get(NO_CACHE_ENV) or index_params.get("max_voxels") is not None:
        return MapIndex(m, max_distance=max_distance, voxel_size=voxel_size, **index_params)
    cf, digest = _cache_file(path, float(max_distance), float(voxel_size), cache_dir)
    if cf.is_file():
        try:
            return _read_index(m, cf, map_digest=digest, max_distance=float(max_distance),
                               voxel_size=float(voxel_size), **index_params)
        except Exception as e:  # a truncated, foreign, tampered or oversized file: never trusted, rebuilt
            warnings.warn(f"{cf}: unreadable index cache, or not this map's ({type(e).__name__}: {e}); rebuilding it",
                          UserWarning, stacklevel=2)
    index = MapIndex(m, max_distance=max_distance, voxel_size=voxel_size, **index_params)
    _write_index(index, cf, digest)
    return index
