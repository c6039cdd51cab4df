"""The matching core's oracle: cv2.StereoBM configured exactly like a MatchParams (tests, benches)."""
from __future__ import annotations

import cv2

from stereocam.stereo import MatchParams


def opencv_stereobm(p: MatchParams):
    """cv2.StereoBM with p's settings (OpenCV 4.x ``StereoBM_create`` or 5.x ``StereoBM.create``)."""
    create = getattr(cv2, "StereoBM_create", None) or cv2.StereoBM.create
    bm = create(numDisparities=p.num_disparities, blockSize=p.block_size)
    bm.setMinDisparity(p.min_disparity)
    bm.setPreFilterType(1 if p.pre_filter_type == "xsobel" else 0)
    bm.setPreFilterSize(p.pre_filter_size)
    bm.setPreFilterCap(p.pre_filter_cap)
    bm.setTextureThreshold(p.texture_threshold)
    bm.setUniquenessRatio(p.uniqueness_ratio)
    bm.setSpeckleWindowSize(p.speckle_window_size)
    bm.setSpeckleRange(p.speckle_range)
    bm.setDisp12MaxDiff(p.disp12_max_diff)
    return bm
