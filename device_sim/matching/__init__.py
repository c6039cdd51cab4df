"""Device matching core: StereoBM-compatible block matching, bit-exact with cv2.StereoBM.

``match(left, right, MatchParams(...))`` returns int16 disparity * 16; ``Matcher`` keeps its
scratch buffers between frames of one shape. OpenCV is only the test oracle, never called here.
"""
from .matcher import Matcher, check_pair, match
from .params import MatchParams, geometry

__all__ = ["MatchParams", "Matcher", "match", "check_pair", "geometry"]
