"""Line segments by geometry: the edgelines detector and the l1 stereo / frame-to-frame
matcher of linetrack, on numpy arrays (no OpenCV). The same code as the Rust tools."""

import os
from typing import Any, Mapping, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

Image = npt.NDArray[Union[np.uint8, np.uint16]]
"""A 2-D grey image (height, width), uint8 or uint16 (scaled to 8 bits, v * 255 / 65535)."""

Segments = npt.NDArray[Union[np.float32, np.float64]]
"""An (N, 4) array of segments, one x0, y0, x1, y1 row each, pixel centres at integers."""

Config = Union[None, Mapping[str, Any], str, "os.PathLike[str]"]
"""The l1 matcher's configuration: None (defaults), a dict with the keys of
configs/l1-matcher.toml (tables as nested dicts), or the path of such a TOML file."""

def detect_lines(
    image: Image,
    *,
    max_segments: int = 100,
    min_length_px: float = 15.0,
    gradient_threshold: int = 16,
    anchor_threshold: int = 8,
    scan_interval: int = 2,
    max_fit_error_px: float = 1.0,
    max_outlier_run: int = 3,
    min_aligned_fraction: float = 0.7,
) -> npt.NDArray[np.float32]:
    """Line segments of a grey image by the edgelines detector: an (N, 4) float32 array of
    x0, y0, x1, y1 rows, longest first, at most max_segments, each at least min_length_px
    long; from (x0, y0) to (x1, y1) the darker side is on the right. The other settings are
    the [edgelines] keys of configs/frontend.toml. Images under 8 pixels a side have none.

    Raises TypeError (not an array, wrong dtype) or ValueError (shape, empty, colour, a
    setting out of range or unknown), naming the culprit."""

def match_stereo(
    left_image: Image,
    right_image: Image,
    left_segments: Segments,
    right_segments: Segments,
    *,
    config: Config = None,
) -> Tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Matches the segments of a rectified stereo pair with the geometric l1 matcher.
    The images (same shape) give the intensity profiles of its photometric check.

    Returns (pairs, costs): pairs (M, 2) int64 of (left index, right index) in increasing
    left index; costs (M,) float64, each match's weighted geometric error (lower is better).
    Raises TypeError, ValueError (bad arrays, non-finite coordinates, a bad config) or
    OSError (an unreadable config file), naming the culprit."""

def match_frames(
    first_image: Image,
    second_image: Image,
    first_segments: Segments,
    second_segments: Segments,
    *,
    config: Config = None,
) -> Tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Matches the segments of two consecutive frames of one camera with the geometric l1
    matcher; arguments, result and errors as for match_stereo."""
