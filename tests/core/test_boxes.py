"""Image boxes: the box of a pose's known joints, and IoU against hand-computed values and a brute-force area count."""

import numpy as np

from core.boxes import box_iou, keypoint_boxes


def test_keypoint_boxes_span_the_known_joints_and_need_two():
    kp = np.array([[[10.0, 50.0], [50.0, 20.0], [30.0, 120.0]], [[0.0, 0.0], [np.nan, 1.0], [4.0, np.nan]]])
    boxes = keypoint_boxes(kp)
    np.testing.assert_allclose(boxes[0], [10, 20, 50, 120])
    assert np.isnan(boxes[1]).all()  # one joint left: no extent
    # Masked joints are left out like NaN ones.
    np.testing.assert_allclose(keypoint_boxes(kp[:1], np.array([[True, True, False]]))[0], [10, 20, 50, 50])


def test_box_iou_by_hand_and_nan_boxes_never_overlap():
    a = np.array([[0.0, 0.0, 2.0, 2.0], [np.nan] * 4])
    b = np.array([[1.0, 1.0, 3.0, 3.0], [0.0, 0.0, 2.0, 2.0], [5.0, 5.0, 6.0, 6.0]])
    np.testing.assert_allclose(box_iou(a, b), [[1 / 7, 1.0, 0.0], [0.0, 0.0, 0.0]])


def test_box_iou_agrees_with_counting_pixels():
    # Reference: integer boxes rasterised on a grid, intersection and union counted cell by cell.
    rng = np.random.default_rng(0)
    lo = rng.integers(0, 30, size=(12, 2))
    boxes = np.hstack([lo, lo + rng.integers(1, 20, size=(12, 2))]).astype(float)

    def mask(b):
        m = np.zeros((60, 60), bool)
        m[int(b[1]):int(b[3]), int(b[0]):int(b[2])] = True
        return m

    masks = [mask(b) for b in boxes]
    ref = np.array([[(m & n).sum() / (m | n).sum() for n in masks] for m in masks])
    np.testing.assert_allclose(box_iou(boxes, boxes), ref, atol=1e-12)
