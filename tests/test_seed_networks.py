"""The shipped networks of every training seed (models/full/<arch>[@<seed>].pt) and their manifests."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from semmatch.segment.shipping import (
    check_shipped_checkpoint,
    file_sha256,
    load_shipped_network,
    shipped_seeds,
    weights_sha256,
)
from semmatch.segment.training import config_differences

MODELS = Path(__file__).resolve().parents[1] / "models" / "full"


def test_every_shipped_checkpoint_matches_its_manifest():
    paths = sorted(MODELS.glob("*.pt"))
    assert {"compact", "strong"} <= {p.stem for p in paths}
    for path in paths:
        manifest = json.loads(path.with_suffix(".json").read_text())
        assert manifest["checkpoint"] == path.name and manifest["network"] == path.stem
        assert manifest["checkpoint_sha256"] == file_sha256(path), path.name
        assert manifest["weights_sha256"] == weights_sha256(path), path.name
        assert manifest["size_bytes"] == path.stat().st_size
        ran = manifest["trained_on"]
        assert ran["device"] in ("cpu", "cuda") and manifest["train_seconds"] > 0 and manifest["trained_at"]


def test_shipped_training_seeds_share_one_recipe():
    for arch, expected in (("compact", [0, 1, 2]), ("strong", [0, 1, 2])):
        seeds = shipped_seeds(MODELS, arch)
        if expected is not None:
            assert list(seeds) == expected
        assert seeds[0] == MODELS / f"{arch}.pt"
        base = json.loads((MODELS / f"{arch}.json").read_text())["train_config"]
        for seed, path in seeds.items():
            cfg = json.loads(path.with_suffix(".json").read_text())["train_config"]
            assert cfg["seed"] == seed
            # the same recipe: only the seed differs (device, threads and paths do not decide the recipe)
            assert [d.split(":")[0] for d in config_differences(base, cfg)] == ([] if seed == 0 else ["seed"]), path.name
    flips = json.loads((MODELS / "recipe.json").read_text())["flip"]
    assert all(name in flips for arch in ("compact", "strong") for name in
               (p.stem for p in shipped_seeds(MODELS, arch).values()))


def test_load_shipped_seed_network_and_refuse_a_changed_file(tmp_path):
    seg = load_shipped_network(MODELS, "compact@1", device="cpu")
    assert seg.info["train_config"]["seed"] == 1
    for name in ("compact.pt", "compact.json", "recipe.json"):
        shutil.copy(MODELS / name, tmp_path / name)
    assert list(shipped_seeds(tmp_path, "compact")) == [0] and shipped_seeds(tmp_path, "strong") == {}
    with pytest.raises(FileNotFoundError, match="no such shipped checkpoint"):
        load_shipped_network(tmp_path, "compact@2")
    manifest = json.loads((tmp_path / "compact.json").read_text())
    (tmp_path / "compact.json").write_text(json.dumps({**manifest, "weights_sha256": "0" * 64}))
    assert check_shipped_checkpoint(tmp_path / "compact.pt")["network"] == "compact"
    with pytest.raises(ValueError, match="weights' SHA-256 differs"):
        load_shipped_network(tmp_path, "compact")
    with (tmp_path / "compact.pt").open("ab") as f:
        f.write(b"\0")
    with pytest.raises(ValueError, match="SHA-256 differs from the one in compact.json"):
        check_shipped_checkpoint(tmp_path / "compact.pt")
    # a file named for one seed whose manifest records another
    shutil.copy(MODELS / "compact.pt", tmp_path / "compact@3.pt")
    (tmp_path / "compact@3.json").write_text(json.dumps(manifest))
    with pytest.raises(ValueError, match="named for training seed 3 but its manifest records seed 0"):
        shipped_seeds(tmp_path, "compact")
