"""COCO-17 to Campus-14 and back, checked joint by joint against evaluate.py's construction."""

import numpy as np

from core.layouts import campus14_to_coco17, coco17_to_campus14
from core.types import CAMPUS14, COCO17


def test_mapping_takes_limb_joints_by_name_and_builds_head_from_nose_and_shoulders():
    coco = np.random.default_rng(1234).normal(0.0, 0.3, (17, 3)) + [0.0, 0.0, 1.0]
    campus = coco17_to_campus14(coco)
    # The twelve limb joints carry the same names in both layouts.
    for name in CAMPUS14.joints[:12]:
        np.testing.assert_array_equal(campus[CAMPUS14.index(name)], coco[COCO17.index(name)])
    # Head: evaluate.py's construction from the mid-shoulders m toward the nose n.
    m = (coco[COCO17.index("left_shoulder")] + coco[COCO17.index("right_shoulder")]) / 2
    n = coco[COCO17.index("nose")]
    np.testing.assert_allclose(campus[12], m + (n - m) * [0.3, 0.4, 0.6])
    np.testing.assert_allclose(campus[13], m + (n - m) * [0.78, 0.5, 1.5])


def test_campus14_to_coco17_keeps_a_head_on_the_evaluated_line():
    # A head that lies where evaluate.py's factors put it is reproduced exactly.
    coco = np.random.default_rng(1).normal(size=(17, 3))
    campus = coco17_to_campus14(coco)
    np.testing.assert_allclose(coco17_to_campus14(campus14_to_coco17(campus)), campus, atol=1e-9)
