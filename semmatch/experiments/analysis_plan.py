"""The analysis plan as the code reads it: the claims, their measures, references and rules.

The plan (``analysis_plan.yaml`` beside this module, explained in ``docs/analysis_plan.md``) fixes
the claims, their comparisons and measures, the references, the interval method, the smallest
effect size of interest (SESOI) per measure, the multiplicity rule and the verdict rules;
:func:`load_analysis_plan` reads it into an :class:`AnalysisPlan` of :class:`Claim` s.
:mod:`semmatch.experiments.summaries` and :mod:`semmatch.experiments.claims` apply it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import yaml

__all__ = [
    "MEASURE_LABELS",
    "VERDICTS",
    "ALL_OTHERS",
    "TOP_HEIGHT",
    "PLAN_FILE",
    "PLAN_V2_FILE",
    "RULES",
    "FRAMES_REFERENCE",
    "Claim",
    "AnalysisPlan",
    "load_analysis_plan",
    "plan_for_seeds",
    "CLAIMS",
]

MEASURE_LABELS = {
    "jaccard": "Jaccard",
    "sorensen": "Sorensen",
    "color_acc": "Color Acc.",
    "mean_acc": "Mean Acc.",
    "miou": "mIoU",
}
VERDICTS = ("holds", "does not hold", "equivalent", "inconclusive")

#: in :attr:`Claim.others`: every other transfer method (tables) or every other height (Fig. 3)
ALL_OTHERS = "<all others>"
#: in :attr:`Claim.others`: the highest camera height of the sweep
TOP_HEIGHT = "<top height>"
#: the analysis plan read by :func:`load_analysis_plan`
PLAN_FILE = Path(__file__).with_name("analysis_plan.yaml")
#: the second analysis plan (issue 52: minimum-effect, intersection-union and "refuted" rules)
PLAN_V2_FILE = Path(__file__).with_name("analysis_plan_v2.yaml")
#: the verdict rules a plan can declare (``rules:`` in its YAML; v1's plan has none: ``v1``)
RULES = ("v1", "v2")

_DATA = {"synthetic": "table2", "real-like": "table3", "height sweep": "fig3", "depth noise": "noise"}
_KINDS = ("beats", "best", "worst", "similar")
_MODELS = ("networks", "ground truth", "all")
_ROLES = ("primary", "secondary")
#: the reference name of Fig. 3's rows (per-frame scores against ground-truth label images)
FRAMES_REFERENCE = "frames"


@dataclass(frozen=True)
class Claim:
    """One comparative claim of the paper and how it is judged.

    Attributes
    ----------
    id : str
        Short id (``C1`` ...).
    statement : str
        The claim in words.
    section : str
        Where the paper makes it.
    data : str
        ``"synthetic"`` (Table 2), ``"real-like"`` (Table 3), ``"height sweep"`` (Fig. 3) or
        ``"depth noise"`` (the depth-noise study's per-scene drops,
        :func:`semmatch.experiments.depth_noise.noise_drops`).
    kind : str
        ``"beats"``, ``"best"``, ``"worst"`` or ``"similar"``.
    subjects : tuple
        The A of the comparison: methods (``"lower"``, ``"upper"`` or a transfer method) or
        camera heights in metres.
    others : tuple
        The B side: methods or heights, :data:`ALL_OTHERS` or :data:`TOP_HEIGHT`.
    measure : str
        The per-scene measure compared.
    models : str
        Upper maps the claim is judged for: ``"networks"``, ``"ground truth"`` or ``"all"``.
    role : str
        ``"primary"`` (confirmatory) or ``"secondary"`` (declared, reported).
    note : str
        Remarks of the plan (e.g. where the paper contradicts itself).
    """

    id: str
    statement: str
    section: str
    data: str
    kind: str
    subjects: tuple[str | float, ...]
    others: tuple[str | float, ...]
    measure: str = "mean_acc"
    models: str = "networks"
    role: str = "primary"
    note: str = ""

    def __post_init__(self) -> None:
        if self.data not in _DATA:
            raise ValueError(f"Claim {self.id}: data must be one of {tuple(_DATA)}, got {self.data!r}")
        if self.kind not in _KINDS:
            raise ValueError(f"Claim {self.id}: kind must be one of {_KINDS}, got {self.kind!r}")
        if self.models not in _MODELS:
            raise ValueError(f"Claim {self.id}: models must be one of {_MODELS}, got {self.models!r}")
        if self.role not in _ROLES:
            raise ValueError(f"Claim {self.id}: role must be one of {_ROLES}, got {self.role!r}")


@dataclass(frozen=True)
class AnalysisPlan:
    """The analysis plan's settings as the code uses them (see ``analysis_plan.yaml``).

    Attributes
    ----------
    claims : tuple of Claim
    sesoi : dict
        Smallest effect size of interest per measure.
    interval : str
        Interval method (:data:`semmatch.evaluate.stats.INTERVAL_METHODS`).
    confidence : float
        Level of the two-sided intervals.
    alpha : float
        Level of the Holm-adjusted one-sided tests.
    min_scenes : int
        Fewer complete scene pairs make a comparison inconclusive.
    primary_reference : str
    secondary_references : tuple of str
    route : str
    speed_claims : tuple of dict
    rules : str
        The verdict rules (:data:`RULES`): ``v1`` (Holm-adjusted tests, the half-count claim rule)
        or ``v2`` (minimum-effect test, intersection-union, ``refuted``, kind clusters).
    version : int
        The plan's ``plan_version``.
    raw : dict
        The whole YAML document.
    """

    claims: tuple[Claim, ...]
    sesoi: dict[str, float]
    interval: str = "t"
    confidence: float = 0.95
    alpha: float = 0.05
    min_scenes: int = 2
    primary_reference: str = "fusion"
    secondary_references: tuple[str, ...] = ("mesh",)
    route: str = "own"
    speed_claims: tuple[dict, ...] = ()
    rules: str = "v1"
    version: int = 1
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def references(self) -> tuple[str, ...]:
        """The primary reference, then the secondary ones."""
        return (self.primary_reference, *self.secondary_references)

    @property
    def one_network_interval(self) -> str:
        """The interval method for tables with one network per architecture (v2's ``one_network_interval``;
        the plan's ``interval`` in a v1 plan)."""
        return str(self.raw.get("inference", {}).get("one_network_interval", self.interval))


def _level(v: object) -> str | float:
    return float(v) if isinstance(v, int | float) else str(v)


def _carried_over(data: dict, source: str) -> tuple[Claim, ...]:
    """The claims a plan carries over from another plan file (``claims_carried_over: {from, ids}``)."""
    spec = data.get("claims_carried_over")
    if not spec:
        return ()
    other = load_analysis_plan(Path(source).with_name(str(spec["from"])))
    by_id = {c.id: c for c in other.claims}
    unknown = [i for i in spec["ids"] if str(i) not in by_id]
    if unknown:
        raise ValueError(f"{source}: claims_carried_over names claims {unknown} that {spec['from']} does not have")
    return tuple(by_id[str(i)] for i in spec["ids"])


def _parse_plan(data: dict, source: str) -> AnalysisPlan:
    try:
        inf, refs = data["inference"], data["references"]
        claims = _carried_over(data, source) + tuple(
            Claim(id=str(c["id"]), statement=str(c["statement"]), section=str(c["section"]), data=c["data"],
                  kind=c["kind"], subjects=tuple(_level(v) for v in c["subjects"]),
                  others=tuple(_level(v) for v in c["others"]), measure=c.get("measure", "mean_acc"),
                  models=c.get("models", "networks"), role=c.get("role", "primary"), note=str(c.get("note", "")))
            for c in data["claims"]
        )
        plan = AnalysisPlan(
            claims=claims, sesoi={str(k): float(v) for k, v in data["sesoi"].items()},
            interval=str(inf["interval"]), confidence=float(inf["confidence"]), alpha=float(inf["alpha"]),
            min_scenes=int(inf["min_scenes"]), primary_reference=str(refs["primary"]),
            secondary_references=tuple(str(r) for r in refs.get("secondary", ())), route=str(data["route"]),
            speed_claims=tuple(data.get("speed_claims", ())), rules=str(data.get("rules", "v1")),
            version=int(data.get("plan_version", 1)), raw=data,
        )
    except (KeyError, TypeError) as e:
        raise ValueError(f"{source}: not a valid analysis plan ({type(e).__name__}: {e})") from e
    if plan.rules not in RULES:
        raise ValueError(f"{source}: rules must be one of {RULES}, got {plan.rules!r}")
    ids = [c.id for c in plan.claims]
    if len(set(ids)) != len(ids):
        raise ValueError(f"{source}: claim ids repeat: {sorted({i for i in ids if ids.count(i) > 1})}")
    missing = sorted({c.measure for c in plan.claims} - set(plan.sesoi))
    if missing:
        raise ValueError(f"{source}: no smallest effect size of interest (sesoi) for {missing}")
    return plan


@lru_cache(maxsize=8)
def _load_cached(path: str, mtime: float) -> AnalysisPlan:
    data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    if not isinstance(data, dict):
        raise ValueError(f"{path}: not a valid analysis plan (expected a YAML mapping)")
    return _parse_plan(data, path)


def load_analysis_plan(path: str | Path | None = None) -> AnalysisPlan:
    """Read the analysis plan.

    Parameters
    ----------
    path : str or Path, optional
        A plan file; default :data:`PLAN_FILE` (the committed plan).

    Returns
    -------
    AnalysisPlan

    Raises
    ------
    ValueError
        If the file is not a valid plan (names the file and what is missing).
    FileNotFoundError
        If the file does not exist.
    """
    p = Path(path) if path is not None else PLAN_FILE
    return _load_cached(str(p.resolve()), p.stat().st_mtime)


def plan_for_seeds(seeds: Sequence[int]) -> AnalysisPlan:
    """The plan a confirmatory run of ``seeds`` is judged by: v2 (:data:`PLAN_V2_FILE`) for its
    confirmatory seeds (8101-8106), else v1 (:data:`PLAN_FILE`: the first run's and readers' runs).

    Raises
    ------
    ValueError
        If ``seeds`` mixes v2's confirmatory seeds with others.
    """
    v2 = load_analysis_plan(PLAN_V2_FILE)
    mine = {int(s) for s in v2.raw["scenes"]["confirmatory_seeds"]}
    given = {int(s) for s in seeds}
    if given & mine and not given <= mine:
        raise ValueError(f"{PLAN_V2_FILE.name}: seeds {sorted(given)} mix the v2 plan's confirmatory seeds "
                         f"{sorted(mine)} with others; run them apart")
    return v2 if given and given <= mine else load_analysis_plan(PLAN_FILE)


#: The comparative claims of the analysis plan (the paper's §4-5 and the abstract's summary of
#: them, plus the plan's declared secondary claims).
CLAIMS: tuple[Claim, ...] = load_analysis_plan().claims
