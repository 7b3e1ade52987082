"""Whether the analysis plan v2 came before every file of its confirmatory seeds, read from git.

The v2 plan is identified by the first commit that added :data:`PLAN_DOC` in ``HEAD``'s history.
Every commit of that history that adds or changes a file whose path names one of the plan's
confirmatory seeds (8101-8106, e.g. ``figures/confirm/seeds-8101-8106/...`` or
``data/.../living_room_8102/...``) must be the plan's commit or descend from it
(``git rev-list --ancestry-path``); :func:`files_before_plan` lists those that do not.
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Sequence
from pathlib import Path

__all__ = ["PLAN_DOC", "SEEDS", "plan_commit", "files_before_plan"]

#: the v2 plan's document; its first commit is the plan's commit
PLAN_DOC = "docs/analysis_plan_v2.md"
#: the v2 plan's confirmatory seeds
SEEDS = (8101, 8102, 8103, 8104, 8105, 8106)


def _git(root: Path, *args: str) -> str:
    try:
        out = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.SubprocessError) as e:
        raise ValueError(f"{root}: git {' '.join(args)} failed ({e})") from e
    if out.returncode != 0:
        raise ValueError(f"{root}: git {' '.join(args)} failed: {out.stderr.strip()}")
    return out.stdout


def plan_commit(root: str | Path = ".", plan_doc: str = PLAN_DOC) -> str:
    """The first commit of ``HEAD``'s history that added ``plan_doc``.

    Raises
    ------
    ValueError
        If git fails there or the history has no commit adding ``plan_doc``.
    """
    added = _git(Path(root), "log", "--format=%H", "--diff-filter=A", "HEAD", "--", plan_doc).split()
    if not added:
        raise ValueError(f"{root}: no commit of HEAD's history adds {plan_doc} (the plan is not committed)")
    return added[-1]


def files_before_plan(root: str | Path = ".", *, seeds: Sequence[int] = SEEDS,
                      plan_doc: str = PLAN_DOC) -> list[tuple[str, str]]:
    """Files of the plan's seeds committed outside the plan's descendants.

    Parameters
    ----------
    root : str or Path
        A git checkout.
    seeds : sequence of int
        The seeds whose files must come after the plan (a path naming one of them as a number).
    plan_doc : str
        The plan's document (its first commit is the plan's).

    Returns
    -------
    list of (commit, path)
        Each commit of ``HEAD``'s history, not the plan's commit nor one descending from it, that
        adds or changes a file whose path names one of ``seeds``; empty when the order holds.

    Raises
    ------
    ValueError
        If git fails or the plan is not in ``HEAD``'s history.
    """
    root = Path(root)
    plan = plan_commit(root, plan_doc)
    after = set(_git(root, "rev-list", "--ancestry-path", f"{plan}..HEAD").split()) | {plan}
    pattern = re.compile(r"(?<!\d)(" + "|".join(str(int(s)) for s in seeds) + r")(?!\d)")
    bad, commit = [], None
    for line in _git(root, "log", "--format=%x00%H", "--name-only", "HEAD").splitlines():
        if line.startswith("\x00"):
            commit = line[1:].strip()
        elif line.strip() and commit not in after and pattern.search(line):
            bad.append((commit, line.strip()))
    return bad
