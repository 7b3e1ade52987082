"""semmatch.sim.appearance: a held-out look that keeps geometry and labels, repeatable, and its recordings."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.sim import Renderer, generate_scene
from semmatch.sim.appearance import (
    HELDOUT_ALBEDOS,
    HELDOUT_TEXTURES,
    ILLUMINANTS,
    HeldOutRenderer,
    heldout_appearance,
    heldout_texture_factor,
    write_heldout_recording,
)
from semmatch.sim.materials import MATERIALS
from semmatch.sim.trajectory import make_trajectory


@pytest.fixture(scope="module")
def scene():
    return generate_scene("office", 11)


def test_the_look_is_held_out_repeatable_and_per_material(scene):
    a, b = heldout_appearance(scene, 11), heldout_appearance(scene, 11)
    np.testing.assert_array_equal(a.scene.albedo, b.scene.albedo)
    np.testing.assert_array_equal(a.texture, b.texture)
    assert not np.array_equal(heldout_appearance(scene, 12).scene.albedo, a.scene.albedo)
    # geometry and labels untouched
    np.testing.assert_array_equal(a.scene.vertices, scene.vertices)
    np.testing.assert_array_equal(a.scene.labels, scene.labels)
    assert a.scene.texture is None and a.illuminant in ILLUMINANTS
    # triangles that shared a material share the new one
    keys = np.concatenate([np.round(scene.albedo, 4), scene.texture[:, None]], axis=1)
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = group.reshape(-1)
    for g in np.unique(group)[:20]:
        sel = group == g
        assert len(np.unique(a.scene.albedo[sel], axis=0)) == 1 and len(np.unique(a.texture[sel])) == 1
    # no new albedo is a training material's (tints and jitter aside: far from every one)
    train = np.array([m.albedo for m in MATERIALS.values()])
    held = np.array(list(HELDOUT_ALBEDOS.values()))
    assert np.min(np.linalg.norm(held[:, None] - train[None], axis=2)) > 0.08
    assert len(a.lights) == 1 and a.ambient < 0.3


def test_texture_factors_stay_around_one():
    rng = np.random.default_rng(0)
    p = rng.uniform(-3, 3, (5000, 3))
    for k, (_, amp, *_rest) in enumerate(HELDOUT_TEXTURES.values()):
        f = heldout_texture_factor(p, np.full(len(p), k))
        assert f.dtype == np.float32 and np.all(np.abs(f - 1) <= amp + 1e-6)
        assert (f.std() > 0.03) == (amp > 0)


def test_the_renderer_changes_rgb_only(scene):
    intr = DEFAULT_INTRINSICS.scaled(80, 60)
    pose = make_trajectory(scene, 1.2, 3, seed=0, kind="upper")[1]
    plain, held = Renderer(scene, intr).render(pose), HeldOutRenderer(heldout_appearance(scene, 11), intr).render(pose)
    np.testing.assert_array_equal(plain.depth, held.depth)
    np.testing.assert_array_equal(plain.labels, held.labels)
    assert np.abs(plain.rgb.astype(int) - held.rgb.astype(int)).mean() > 20


def test_recording_errors(tmp_path):
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "meta.json").write_text('{"scene_meta": {"kind": "office"}, "noise": {}}')
    with pytest.raises(ValueError, match="no scene_meta kind and seed"):
        write_heldout_recording(tmp_path / "rec", tmp_path / "out")
    (tmp_path / "rec" / "meta.json").write_text('{"scene_meta": {"kind": "office", "seed": 3}}')
    with pytest.raises(ValueError, match="no 'noise' settings"):
        write_heldout_recording(tmp_path / "rec", tmp_path / "out")
    (tmp_path / "out").mkdir()
    with pytest.raises(FileExistsError, match="out: exists"):
        write_heldout_recording(tmp_path / "rec", tmp_path / "out")


def test_severity_blends_the_training_and_held_out_looks(scene):
    full, half = heldout_appearance(scene, 11), heldout_appearance(scene, 11, 0.5)
    np.testing.assert_array_equal(full.texture, half.texture)  # the same draws
    assert half.severity == 0.5 and half.scene.texture is not None  # training textures kept for the blend
    d_full = np.abs(full.scene.albedo - scene.albedo).mean()
    d_half = np.abs(half.scene.albedo - scene.albedo).mean()
    assert 0.2 * d_full < d_half < 0.8 * d_full
    intr = DEFAULT_INTRINSICS.scaled(80, 60)
    pose = make_trajectory(scene, 1.2, 3, seed=0, kind="upper")[1]
    plain = Renderer(scene, intr).render(pose).rgb.astype(int)
    gaps = [np.abs(HeldOutRenderer(heldout_appearance(scene, 11, s), intr).render(pose).rgb.astype(int) - plain).mean()
            for s in (0.25, 0.5, 1.0)]
    assert gaps[0] < gaps[1] < gaps[2]
    for bad in (0.0, -0.1, 1.5):
        with pytest.raises(ValueError, match="severity must be in"):
            heldout_appearance(scene, 11, bad)
