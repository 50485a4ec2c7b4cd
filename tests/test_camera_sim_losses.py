"""simulate (camera) says why corners were not detected: each lost corner counted under one cause (behind the
camera, outside the image), the counts those of the NaN pixels written; a design's poses lose corners when the
truth's errors move them past the design's image margin, and the summary says so."""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.simulation.camera_sim import (LOSS_CAUSES, CameraTolerances, camera_truth, lost_corners_text,
                                               simulate_corners, simulate_detections)
from tests.camera_setup import Q0, ur5_camera


def test_every_lost_corner_is_counted_under_one_cause():
    model = ur5_camera("eye_in_hand")
    Q = model.views(12, seed=5, around=Q0[None])
    # a truth far off nominal (the camera 0.1 rad off on the tool): part of the board leaves the image
    p = camera_truth(model, CameraTolerances(hand_eye_rotation_rad=0.1, board_rotation_rad=0.1), seed=1)
    uv, lost = simulate_detections(model, Q, p, seed=2)
    assert set(lost) == set(LOSS_CAUSES) and all(v.shape == (len(Q),) for v in lost.values())
    nan = np.isnan(uv[:, ::2]).sum(axis=1)
    assert nan.sum() > 0 and np.array_equal(nan, lost["behind the camera"] + lost["outside the image"])
    assert lost["outside the image"].sum() > 0
    np.testing.assert_array_equal(uv, simulate_corners(model, Q, p, seed=2))   # the same pixels, the same noise
    text = lost_corners_text({k: int(v.sum()) for k, v in lost.items()}, designed=True)
    assert f"{int(lost['outside the image'].sum())} outside the image" in text and "image margin" in text
    assert "none to the viewing angle or to occlusion" in text
    assert lost_corners_text({c: 0 for c in LOSS_CAUSES}, designed=True) == ""
