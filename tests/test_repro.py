"""repro/common.py: the deformed world of paper B's robustness test (the scripts themselves run in `make reproduce`)."""

from __future__ import annotations

import importlib.util

import numpy as np

from .conftest import REPO, SMALL_MAP, build_map


def _common():
    spec = importlib.util.spec_from_file_location("repro_common", REPO / "repro" / "common.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_rotate_map_turns_obstacles_landmarks_and_starts_about_the_center():
    common = _common()
    map_ = build_map(SMALL_MAP)
    center = np.array([5.0, 4.0])
    turned = common.rotate_map(map_, 90.0, tuple(center))

    def quarter_turn(p):  # (x, y) -> c + (-(y - cy), x - cx)
        d = np.asarray(p) - center
        return center + np.column_stack([-d[:, 1], d[:, 0]])

    np.testing.assert_allclose(turned.landmarks, quarter_turn(map_.landmarks), atol=1e-12)
    np.testing.assert_allclose(turned.starts, quarter_turn(map_.starts), atol=1e-12)
    for before, after in zip(map_.obstacles + map_.raw_obstacles, turned.obstacles + turned.raw_obstacles, strict=True):
        np.testing.assert_allclose(after.exterior, quarter_turn(before.exterior), atol=1e-12)
    np.testing.assert_array_equal(turned.goal, map_.goal)
    np.testing.assert_array_equal(turned.bounds, map_.bounds)
    assert turned.landmark_ids == map_.landmark_ids

    same = common.rotate_map(map_, 0.0, (130.0, 110.0))
    np.testing.assert_allclose(same.landmarks, map_.landmarks, atol=1e-12)
