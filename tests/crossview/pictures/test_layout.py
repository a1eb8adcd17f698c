"""Top-down pictures: each camera's field of view on the floor is where its image border meets the floor."""

import numpy as np

from core.projection import in_image
from crossview.pictures.layout import floor_footprint
from sim import scenario as scenario_mod
from sim.cameras import build_rig
from sim.rng import child_rng


def test_floor_footprint_projects_back_onto_the_image_border():
    scenario = scenario_mod.load("store_layout2")
    for camera in build_rig(scenario, child_rng(0, "cameras"))[::5]:
        footprint = floor_footprint(camera)
        assert len(footprint) == 4 * 24  # ceiling cameras: every border ray reaches the floor
        px, inside = in_image(camera, np.column_stack([footprint, np.zeros(len(footprint))]))
        # Through the camera's own lens (OpenCV's model) the floor points land on the border pixels again.
        to_border = np.minimum.reduce([px[:, 0], camera.width_px - 1 - px[:, 0], px[:, 1],
                                       camera.height_px - 1 - px[:, 1]])
        np.testing.assert_allclose(to_border, 0.0, atol=1e-3)  # px (OpenCV undistorts by a few iterations)
