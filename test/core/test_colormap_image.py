"""Force colours (against matplotlib's viridis) and tactile images."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_ros.core.colormap import STALE_RGB, VIRIDIS_RGB, force_colours
from tactile_descriptors_ros.core.geometry import layout_2d
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.core.tactile_image import BACKGROUND_RGB, image_layout, render


def test_colour_table_is_matplotlibs_viridis():
    matplotlib = pytest.importorskip("matplotlib")
    ref = matplotlib.colormaps["viridis"](np.linspace(0, 1, 256))[:, :3] * 255
    assert np.abs(VIRIDIS_RGB.astype(float) - ref).max() <= 0.5


def test_fixed_scale_clips_and_greys():
    rgb = force_colours([0.0, 1.5, 3.0, 7.0, -1.0, np.nan], 3.0)
    assert (rgb[0] == VIRIDIS_RGB[0]).all() and (rgb[1] == VIRIDIS_RGB[128]).all()
    assert (rgb[2] == VIRIDIS_RGB[255]).all() and (rgb[3] == VIRIDIS_RGB[255]).all()
    assert (rgb[4] == VIRIDIS_RGB[0]).all() and tuple(rgb[5]) == STALE_RGB
    assert not any((VIRIDIS_RGB == STALE_RGB).all(axis=1))  # grey is no force
    with pytest.raises(ValueError):
        force_colours([1.0], 0.0)


@pytest.mark.parametrize("name", ["shadow_hand", "nao"])
def test_every_sensing_point_gets_its_own_disc(name):
    robot = load_robot(name)
    for part in robot.body_parts:
        tax = robot.geometry.taxels(robot, part.name)
        lay = image_layout(layout_2d(tax.positions, tax.normals), 96)
        labels, counts = np.unique(lay.label[lay.label >= 0], return_counts=True)
        assert labels.tolist() == list(range(len(tax))), part.name
        assert counts.min() >= 3.14 * (lay.radius_px - 1) ** 2 * 0.8  # discs, not slivers
        colours = force_colours(np.linspace(0, 3, len(tax)), 3.0)
        img = render(lay, colours)
        assert img.shape == (96, 96, 3) and img.dtype == np.uint8
        for k, (c, r) in enumerate(np.rint(lay.centres_px).astype(int)):
            assert (img[r, c] == colours[k]).all()
        assert (img[0, 0] == BACKGROUND_RGB).all()


def test_a_layout_too_dense_for_the_image_is_refused():
    pts = np.stack([np.linspace(0, 1, 200), np.zeros(200)], axis=1)
    with pytest.raises(ValueError, match="do not fit"):
        image_layout(pts, 16)
