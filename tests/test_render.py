"""world.render: frames drawn from a pose, tags detected by OpenCV, the Controller driven from them."""

from __future__ import annotations

import math
from types import SimpleNamespace

# OpenCV comes with the test extra (bearnav[camera]): a broken install fails here rather than skipping
import cv2  # noqa: F401
import numpy as np
import pytest

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.geometry import FreeSpace
from bearnav_cli.runtime import Controller
from bearnav_cli.world.render import RenderedCamera, RenderSettings

from .conftest import build_map

#: A 6 m × 4 m room with a block in the middle; tags on the walls and on the block.
ROOM = {
    "name": "room", "bounds": [0, 0, 6, 4], "robot_radius": 0.2, "goal": [0.6, 0.6], "starts": [[5.3, 3.3]],
    "obstacles": [{"rectangle": [2.5, 1.6, 3.5, 2.4]}],
    "landmarks": [{"id": f"tag{k}", "position": p} for k, p in enumerate([
        [0, 1.0], [0, 2.0], [0, 3.0], [1.5, 0], [3.0, 0], [4.5, 0], [6, 1.0], [6, 2.0], [6, 3.0],
        [1.5, 4], [3.0, 4], [4.5, 4], [2.5, 2.0], [3.5, 2.0], [3.0, 1.6], [3.0, 2.4],
    ])],
    "params": {"rrtstar": {"iterations": 400, "step": 0.5, "seed": 0}},
}  # fmt: skip


@pytest.fixture(scope="module")
def room():
    return build_map(ROOM)


def _camera(map_, **settings):
    return RenderedCamera(map_, rng=np.random.default_rng(0), settings=RenderSettings(**settings))


def _errors_deg(cam, x, b, seen):
    d = cam.tags.positions[seen] - x
    true = np.arctan2(d[:, 1], d[:, 0])
    return np.degrees(np.abs(np.angle(np.exp(1j * (np.arctan2(b[seen, 1], b[seen, 0]) - true)))))


def test_a_frame_shows_every_tag_in_view_and_sight(room):
    cam = _camera(room)
    x, heading = np.array([1.2, 2.0]), 0.0  # facing the block: its west face, the right wall behind it
    img = cam.render(x, heading)
    assert img.shape == (cam.settings.height, cam.settings.width) and img.dtype == np.uint8
    expected, edge = cam.expected(x, heading)
    bearings, seen = cam.measure(np.array([0]), x[None], np.array([heading]))
    assert expected[12] and not expected[13]  # the block's west tag; its east tag faces away
    assert not expected[7]  # the right wall's middle tag is behind the block
    # every tag shown whole and large enough to decode is found; nothing that is not shown whole
    assert not (expected & (edge >= 12) & ~seen[0]).any() and not (seen[0] & ~expected).any()
    assert seen[0].sum() >= 3
    assert _errors_deg(cam, x, bearings[0], seen[0]).max() < 0.5
    report = cam.report()
    assert report["frames"] == 1 and report["matched"] == seen.sum() and report["bearing_error_deg"]["max"] < 0.5


def test_tags_behind_walls_or_outside_the_view_are_not_detected(room):
    cam = _camera(room)
    x = np.array([1.2, 2.0])
    # looking at the left wall: tags 0-2 ahead; everything on the right is outside the 90° view
    _, seen = cam.measure(np.array([0]), x[None], np.array([math.pi]))
    assert seen[0, :3].any() and not seen[0, 6:9].any() and not seen[0, 12:].any()
    # from behind the block the tag on its west face is hidden
    _, seen = cam.measure(np.array([0]), np.array([[4.8, 2.0]]), np.array([math.pi]))
    assert not seen[0, 12] and not cam.expected(np.array([4.8, 2.0]), math.pi)[0][12]


def test_a_pinhole_needs_a_field_of_view_below_175_degrees(room):
    plan = SimpleNamespace(map=room)
    with pytest.raises(InvalidParamsError, match="--fov below 175") as err:
        RenderedCamera.for_plan(plan, fov=math.radians(360), rng=np.random.default_rng(0))
    assert err.value.field == "fov"
    cam = RenderedCamera.for_plan(plan, fov=math.radians(60), rng=np.random.default_rng(0))
    assert cam.intrinsics.hfov == pytest.approx(math.radians(60))


def test_the_controller_reaches_the_goal_from_rendered_frames(cli, write_map, tmp_path):
    result = cli("plan", write_map(ROOM, "room.yaml"), "--quiet", "-o", "room")
    assert result.exit_code == 0, result.output
    plan_path = str(tmp_path / "room" / "plan.npz")
    from bearnav_cli import artifacts

    plan = artifacts.load(plan_path, "plan").artifact
    fov = math.radians(90)
    cam = RenderedCamera.for_plan(plan, fov=fov, rng=np.random.default_rng(1))
    space = FreeSpace.from_map(plan.map)
    x, phi = plan.map.starts[0].copy(), math.atan2(*(plan.map.goal - plan.map.starts[0])[::-1])
    ctl = Controller.from_plan(plan_path, fov=fov, heading=phi)
    for _ in range(2000):
        if np.hypot(*(x - plan.map.goal)) <= float(plan.goal_tolerance):
            break
        bearings, seen = cam.measure(np.array([0]), x[None], np.array([phi]))
        v = ctl.command(bearings[0], seen[0], heading=phi)
        assert not ctl.lost
        q = x + ctl.settings.dt * v
        assert space.segments_free(x[None], q[None])[0]
        x = q
        d = ctl.state.last_dir[0]
        phi = phi + ctl.settings.dt * ctl.last.turn[0] if ctl.last.scanning[0] else math.atan2(d[1], d[0])
    assert np.hypot(*(x - plan.map.goal)) <= float(plan.goal_tolerance)
    report = cam.report()
    assert report["matched"] > report["frames"] and report["bearing_error_deg"]["p95"] < 0.5


def test_the_heading_from_detected_tag_poses(room):
    """The paper's W_R_J = W_R_AT · (J_R_AT)⁻¹ on OpenCV's poses of rendered tags: near tags give the
    heading within a few degrees (far, small ones much worse: docs/camera.md)."""
    cam = _camera(room, heading="tags")
    for x, heading in (([0.9, 2.0], math.pi), ([0.9, 1.8], math.pi - 0.3), ([1.0, 2.2], 0.3 - math.pi)):
        bearings, seen = cam.measure(np.array([0]), np.array([x]), np.array([heading]))
        assert seen[0, 1]
    report = cam.report()
    assert report["heading_error_deg"]["max"] < 3.0 and report["bearing_error_deg"]["max"] < 3.0


def test_the_filter_of_a_rendered_run_never_assumes_exact_bearings(room):
    """A detector's bearings err a little: the simulated robot's filter assumes at least what the
    Controller does (with exact fixes assumed, 2 of the kitchen's 4 default starts got lost)."""
    from bearnav_cli.runtime.settings import BEARING_SIGMA
    from bearnav_cli.stages import simulate

    plan = SimpleNamespace(map=room, goal_tolerance=0.1)
    for noise, camera, expected in (
        (0.0, "ideal", 0.0),
        (0.0, "render", BEARING_SIGMA),
        (3.0, "render", math.radians(3.0)),
    ):
        s = simulate.settings(plan, simulate.Params(noise_deg=noise, camera=camera, fov=90.0))
        assert s.control.bearing_sigma == pytest.approx(expected)
