"""The evaluation protocol's checks, run before any pipeline work starts.

A profile of ``params.yaml`` names its scene splits in ``common``: ``train_seeds`` (the networks
learn from them), ``val_seeds`` (every recipe choice is made on them: checkpoint selection,
test-time flip, odometry gate), ``eval_seeds`` (every table is computed on them; in the full
profile they are the development scenes 7001-7003, looked at in earlier runs, and confirmatory
scenes come from ``make confirm``) and ``dev_seeds`` (scenes that were looked at during an
earlier round, recorded so that they can never become evaluation scenes). ``min_val_per_kind`` asks for validation
scenes of every kind.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping

__all__ = ["check_protocol", "validation_kinds", "preflight_scenes", "RESERVED_EVAL_PROFILES", "RETIRED_SEEDS", "used_seeds",
           "check_confirm_seeds"]

#: profiles whose evaluation seeds nobody has generated: held back for confirmatory runs (``make
#: confirm``), so they are not refused there; every other profile's evaluation seeds were scored
#: during development
RESERVED_EVAL_PROFILES: tuple[str, ...] = ("large",)

#: seeds generated while developing that no profile lists any more: refused by ``make confirm`` too
RETIRED_SEEDS: dict[int, str] = {
    9001: "former development evaluation seed (profile smoke)",
    **{s: "smoke candidate scored while choosing smoke's evaluation seed (params.yaml, profile smoke)"
       for s in (9003, 9004, 9005)},
}

#: the scene splits of a profile's ``common`` section, in the words the refusal uses
_SPLITS = {"train_seeds": "training", "val_seeds": "validation", "dev_seeds": "development",
           "eval_seeds": "development evaluation"}


def validation_kinds(kinds: list[str], val_seeds: list[int]) -> Counter:
    """How many validation scenes of each kind ``val_seeds`` give (seed ``i``: ``kinds[i % len(kinds)]``)."""
    return Counter(kinds[i % len(kinds)] for i in range(len(val_seeds)))


def check_protocol(common: Mapping, *, where: str = "params.yaml") -> None:
    """Refuse a profile whose splits break the protocol, before any work starts.

    Parameters
    ----------
    common : mapping
        The profile's ``common`` section (``kinds``, ``train_seeds``, ``val_seeds``,
        ``eval_seeds``, optional ``dev_seeds`` and ``min_val_per_kind``). A section with
        neither ``kinds`` nor ``eval_seeds`` defines no scenes and is not checked.
    where : str
        Named in the messages.

    Raises
    ------
    ValueError
        An empty evaluation seed list, overlapping splits, evaluation seeds that were used
        during development, an unknown scene kind, or fewer validation scenes of a kind than
        ``min_val_per_kind``.
    """
    from ..sim import SCENE_KINDS, check_seed_splits

    if "eval_seeds" not in common and "kinds" not in common:
        return  # a parameter file without scene splits (e.g. one notebook's own)
    kinds = list(common.get("kinds") or [])
    if not kinds:
        raise ValueError(f"{where}: common.kinds is empty")
    unknown = [k for k in kinds if k not in SCENE_KINDS]
    if unknown:
        raise ValueError(f"{where}: unknown scene kind(s) {unknown}; valid: {', '.join(SCENE_KINDS)}")
    try:
        check_seed_splits(common.get("train_seeds") or [], common.get("val_seeds") or [],
                          common.get("eval_seeds") or [], dev_seeds=common.get("dev_seeds") or [])
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    need = int(common.get("min_val_per_kind") or 0)
    if need:
        have = validation_kinds(kinds, list(common.get("val_seeds") or []))
        short = {k: have.get(k, 0) for k in kinds if have.get(k, 0) < need}
        if short:
            raise ValueError(f"{where}: validation needs >= {need} scene(s) of every kind (min_val_per_kind); "
                             f"val_seeds give {dict(short)} (seed i is of kind kinds[i % {len(kinds)}])")


def preflight_scenes(kinds: list[str], seeds_by_split: Mapping[str, list[int]],
                     heights: tuple[float, ...]) -> None:
    """Check that every evaluation / validation scene can be generated and flown at ``heights``.

    Generates each scene and its free space at every height (about a second a scene), so that
    a profile that cannot be generated fails before hours of work, naming the scene.

    Raises
    ------
    ValueError
        Naming the split, kind, seed and the generator's reason.
    """
    from ..sim import free_space, generate_scene

    for split, seeds in seeds_by_split.items():
        for i, seed in enumerate(seeds):
            scene_kinds = kinds if split == "eval" else [kinds[i % len(kinds)]]
            for kind in scene_kinds:
                try:
                    scene = generate_scene(kind, int(seed))
                    for h in heights:
                        free_space(scene, float(h))
                except ValueError as e:
                    raise ValueError(f"{split} scene {kind} seed {seed} cannot be generated or flown: {e}") from None


def used_seeds(profiles: Mapping[str, Mapping]) -> dict[int, dict[str, list[str]]]:
    """Every scene seed some profile already uses, with where it is used.

    Parameters
    ----------
    profiles : mapping
        ``params.yaml``'s ``profiles`` section.

    Returns
    -------
    dict
        Seed -> {split: sorted profile names}, the split one of ``training``, ``validation``,
        ``development``, ``development evaluation``; the evaluation seeds of
        :data:`RESERVED_EVAL_PROFILES` are not included.
    """
    used: dict[int, dict[str, set[str]]] = {}
    for name, profile in profiles.items():
        common = (profile or {}).get("common") or {}
        for key, split in _SPLITS.items():
            if key == "eval_seeds" and name in RESERVED_EVAL_PROFILES:
                continue
            for seed in common.get(key) or []:
                used.setdefault(int(seed), {}).setdefault(split, set()).add(str(name))
    return {seed: {split: sorted(names) for split, names in by_split.items()} for seed, by_split in used.items()}


def check_confirm_seeds(seeds, profiles: Mapping[str, Mapping], *, where: str = "params.yaml") -> list[int]:
    """Refuse confirmatory seeds that are not fresh scenes; return them as integers.

    A confirmatory run must be on scenes nobody generated while developing: a seed that any
    profile uses for training, validation or development (including the evaluation seeds of
    every profile but :data:`RESERVED_EVAL_PROFILES`, e.g. the full profile's 7001-7003), or
    one of :data:`RETIRED_SEEDS` (e.g. smoke's former 9001), is refused, naming the seed and its split.

    Parameters
    ----------
    seeds : iterable of int-like
        The seeds asked for (each gives one scene of every kind).
    profiles : mapping
        ``params.yaml``'s ``profiles`` section.
    where : str
        Named in the messages.

    Raises
    ------
    ValueError
        No seeds, a seed that is not a non-negative integer, a repeated seed, or a used seed.
    """
    out = []
    for s in seeds:
        try:
            seed = int(str(s))
        except ValueError:
            raise ValueError(f"confirmatory seed {s!r} is not an integer") from None
        if seed < 0:
            raise ValueError(f"confirmatory seed {seed} is negative")
        out.append(seed)
    if not out:
        raise ValueError("no confirmatory seeds given (e.g. SEEDS=\"9101 9102 9103\")")
    repeated = sorted({s for s in out if out.count(s) > 1})
    if repeated:
        raise ValueError(f"confirmatory seed(s) {repeated} given more than once")
    used = used_seeds(profiles)
    refused = [f"seed {s} is a " + " and a ".join(f"{split} seed (profile {', '.join(names)})"
                                               for split, names in used[s].items())
               for s in out if s in used]
    refused += [f"seed {s} is a {RETIRED_SEEDS[s]}" for s in out if s in RETIRED_SEEDS and s not in used]
    if refused:
        raise ValueError(f"{where}: refusing confirmatory seeds already used for training, validation or "
                         f"development: {'; '.join(refused)}. Confirmatory scenes must be ones nobody has generated.")
    return out
