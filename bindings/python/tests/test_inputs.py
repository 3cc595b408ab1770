"""What the functions accept and refuse: every bad input raises a Python exception naming
the argument (never a crash), and the layouts numpy can give an image or a segment array
(views, crops, reversed, transposed, uint16) give what their contiguous copy gives."""

import threading

import numpy as np
import pytest

import linetrack


def scene(height=120, width=160):
    """A dark image with a bright box and a bright triangle (straight edges, four slants)."""
    y, x = np.mgrid[0:height, 0:width]
    box = (x >= width // 5) & (x < width // 2) & (y >= height // 4) & (y < 3 * height // 4)
    triangle = (x > 3 * width // 5) & (y > height // 5) & (x - 3 * width // 5 < y - height // 5)
    return np.where(box | triangle, 200, 7).astype(np.uint8)


IMAGE = scene()
SEGMENTS = linetrack.detect_lines(IMAGE)


def test_the_scene_has_segments_in_the_image():
    assert SEGMENTS.shape[1] == 4 and len(SEGMENTS) >= 4 and SEGMENTS.dtype == np.float32
    assert SEGMENTS[:, [0, 2]].min() >= 0 and SEGMENTS[:, [0, 2]].max() <= IMAGE.shape[1] - 1
    assert SEGMENTS[:, [1, 3]].min() >= 0 and SEGMENTS[:, [1, 3]].max() <= IMAGE.shape[0] - 1
    lengths = np.hypot(SEGMENTS[:, 2] - SEGMENTS[:, 0], SEGMENTS[:, 3] - SEGMENTS[:, 1])
    assert np.all(np.diff(lengths) <= 0), "longest first"


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int16, np.int32, np.bool_, np.uint32])
def test_a_wrong_dtype_is_refused_naming_it(dtype):
    with pytest.raises(TypeError, match=f"image has dtype .*{np.dtype(dtype).name}.*uint8 or uint16"):
        linetrack.detect_lines(IMAGE.astype(dtype))


def test_a_foreign_byte_order_is_refused_naming_it():
    with pytest.raises(TypeError, match="image has dtype >u2, not in this machine's byte order"):
        linetrack.detect_lines(IMAGE.astype(">u2"))
    with pytest.raises(TypeError, match="right_segments has dtype >f8, not in this machine's byte order"):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS.astype(">f8"))


@pytest.mark.parametrize("shape", [(0, 5), (5, 0), (0, 0)])
def test_an_empty_image_is_refused(shape):
    with pytest.raises(ValueError, match=r"image has shape \(.*\): an empty image"):
        linetrack.detect_lines(np.zeros(shape, np.uint8))


@pytest.mark.parametrize("channels", [3, 4])
def test_a_colour_image_is_refused_naming_its_shape(channels):
    colour = np.repeat(IMAGE[:, :, None], channels, axis=2)
    with pytest.raises(ValueError, match=rf"image has shape \(120, 160, {channels}\): {channels} channels"):
        linetrack.detect_lines(colour)


@pytest.mark.parametrize("shape", [(10,), (2, 3, 4, 5), ()])
def test_other_dimensions_are_refused(shape):
    with pytest.raises(ValueError, match="expected a 2-D grey image"):
        linetrack.detect_lines(np.zeros(shape, np.uint8))


@pytest.mark.parametrize("value", [[[1, 2], [3, 4]], None, "image.png", 3])
def test_a_non_array_is_refused(value):
    with pytest.raises(TypeError, match="image must be a numpy.ndarray"):
        linetrack.detect_lines(value)


def test_images_under_8_pixels_a_side_have_no_segments():
    for shape in [(7, 100), (100, 7), (1, 1)]:
        assert linetrack.detect_lines(np.full(shape, 9, np.uint8)).shape == (0, 4)


@pytest.mark.parametrize("view", [
    lambda a: a[10:-7, 13:-5],            # a crop: strided rows, read in place
    lambda a: a[::-1, :],                 # negative row stride: copied
    lambda a: a[:, ::2],                  # columns apart: copied
    lambda a: np.asfortranarray(a),       # column-major: copied
    lambda a: a.T.copy().T,               # the same by transposition
    lambda a: np.pad(a, ((0, 0), (0, 3)))[:, :-3],  # padded rows
])
def test_every_layout_gives_what_its_contiguous_copy_gives(view):
    image = view(IMAGE)
    expected = linetrack.detect_lines(np.ascontiguousarray(image))
    assert len(expected) >= 2
    np.testing.assert_array_equal(linetrack.detect_lines(image), expected)


def test_uint16_is_scaled_to_8_bits():
    wide = IMAGE.astype(np.uint16) * 257  # v * 257 * 255 / 65535 = v exactly
    np.testing.assert_array_equal(linetrack.detect_lines(wide), SEGMENTS)


def test_settings_are_the_config_files_keys_and_are_checked():
    assert len(linetrack.detect_lines(IMAGE, max_segments=2)) == 2
    lengths = np.hypot(SEGMENTS[:, 2] - SEGMENTS[:, 0], SEGMENTS[:, 3] - SEGMENTS[:, 1])
    threshold = float(np.median(lengths)) + 0.5
    longer = linetrack.detect_lines(IMAGE, min_length_px=threshold)
    assert 0 < len(longer) < len(SEGMENTS)
    assert np.all(np.hypot(longer[:, 2] - longer[:, 0], longer[:, 3] - longer[:, 1]) >= threshold)
    assert len(linetrack.detect_lines(IMAGE, gradient_threshold=2000)) == 0
    with pytest.raises(ValueError, match="unknown field `gradient_treshold`"):
        linetrack.detect_lines(IMAGE, gradient_treshold=3)
    with pytest.raises(ValueError, match="edgelines.scan_interval"):
        linetrack.detect_lines(IMAGE, scan_interval=0)
    with pytest.raises(ValueError, match="lines.min_length_px"):
        linetrack.detect_lines(IMAGE, min_length_px=float("nan"))
    with pytest.raises(ValueError, match="min_aligned_fraction"):
        linetrack.detect_lines(IMAGE, min_aligned_fraction="high")
    with pytest.raises(ValueError, match="integer `-1`, expected usize in `max_segments`"):
        linetrack.detect_lines(IMAGE, max_segments=-1)
    with pytest.raises(ValueError, match="expected usize in `max_segments`"):
        linetrack.detect_lines(IMAGE, max_segments=2**70)
    with pytest.raises(ValueError, match="expected u16 in `gradient_threshold`"):
        linetrack.detect_lines(IMAGE, gradient_threshold=70000)
    with pytest.raises(ValueError, match="unknown field `max_segment`.*or `max_segments`"):
        linetrack.detect_lines(IMAGE, max_segment=3)
    assert len(linetrack.detect_lines(IMAGE, max_segments=None)) == len(SEGMENTS)


def test_match_gives_index_pairs_and_costs():
    shifted = np.roll(IMAGE, -6, axis=1)
    right = linetrack.detect_lines(shifted)
    pairs, costs = linetrack.match_stereo(IMAGE, shifted, SEGMENTS, right)
    assert pairs.shape == (len(costs), 2) and len(costs) >= 2
    # Every match is a segment and (part of) its copy 6 px to the left: the right
    # segment's endpoints lie on the left segment's line moved by 6 px.
    left, matched = SEGMENTS[pairs[:, 0]].astype(np.float64), right[pairs[:, 1]]
    direction = left[:, 2:] - left[:, :2]
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1) / np.hypot(*direction.T)[:, None]
    for end in (matched[:, :2], matched[:, 2:]):
        offsets = np.sum((end + [6, 0] - left[:, :2]) * normal, axis=1)
        np.testing.assert_allclose(offsets, 0, atol=0.05)
    assert np.all(costs >= 0)
    pairs, costs = linetrack.match_frames(IMAGE, shifted, SEGMENTS, right)
    assert len(pairs) >= 2
    empty = np.zeros((0, 4), np.float32)
    pairs, costs = linetrack.match_stereo(IMAGE, shifted, empty, right)
    assert pairs.shape == (0, 2) and costs.shape == (0,)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_non_finite_segment_is_refused_naming_its_row(bad):
    segments = SEGMENTS.astype(np.float64)
    segments[2, 1] = bad
    with pytest.raises(ValueError, match=r"right_segments\[2\] = .*not finite"):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, segments)


@pytest.mark.parametrize("segments, error, message", [
    (np.zeros((3, 3), np.float32), ValueError, r"left_segments has shape \(3, 3\): expected \(N, 4\)"),
    (np.zeros(4, np.float32), ValueError, r"left_segments has shape \(4,\)"),
    (np.zeros((3, 4), np.int32), TypeError, "left_segments has dtype int32: expected float32 or float64"),
    ([[0.0, 1.0, 2.0, 3.0]], TypeError, "left_segments must be a numpy.ndarray"),
])
def test_bad_segment_arrays_are_refused(segments, error, message):
    with pytest.raises(error, match=message):
        linetrack.match_stereo(IMAGE, IMAGE, segments, SEGMENTS)


def test_non_contiguous_segments_give_what_their_copy_gives():
    right = linetrack.detect_lines(np.roll(IMAGE, -6, axis=1))
    wide = np.zeros((len(SEGMENTS), 8), np.float64)
    wide[:, ::2] = SEGMENTS
    expected = linetrack.match_stereo(IMAGE, np.roll(IMAGE, -6, axis=1), SEGMENTS, right)
    got = linetrack.match_stereo(IMAGE, np.roll(IMAGE, -6, axis=1), wide[:, ::2], np.asfortranarray(right))
    for a, b in zip(got, expected):
        np.testing.assert_array_equal(a, b)


def test_images_of_different_shapes_are_refused():
    with pytest.raises(ValueError, match=r"left_image has shape \(120, 160\) but right_image has shape \(120, 150\)"):
        linetrack.match_stereo(IMAGE, IMAGE[:, :150], SEGMENTS, SEGMENTS)
    with pytest.raises(ValueError, match="second_image has shape"):
        linetrack.match_frames(IMAGE, np.zeros((120, 160, 3), np.uint8), SEGMENTS, SEGMENTS)


def test_bad_configs_are_refused_naming_the_culprit(tmp_path):
    with pytest.raises(ValueError, match="unknown field `lambada`"):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS, config={"lambda": 0.1, "lambada": 1})
    with pytest.raises(ValueError, match="field `lambda` = -1"):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS, config={"lambda": -1.0})
    with pytest.raises(ValueError, match="expected a boolean in `gates.enabled`"):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS, config={"gates": {"enabled": "yes"}})
    with pytest.raises(TypeError, match="config must be None, a dict or the path"):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS, config=3)
    with pytest.raises(TypeError, match=r"gates.max_angle_deg: a object is not a setting"):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS, config={"gates": {"max_angle_deg": object()}})
    missing = tmp_path / "missing.toml"
    with pytest.raises(OSError, match=str(missing)):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS, config=missing)
    broken = tmp_path / "broken.toml"
    broken.write_text("lambda = [\n")
    with pytest.raises(ValueError, match=str(broken)):
        linetrack.match_stereo(IMAGE, IMAGE, SEGMENTS, SEGMENTS, config=broken)


def test_a_kept_detector_gives_what_a_new_one_gives():
    # Each thread keeps its last few detectors (one per setting) with their buffers: results
    # must not depend on what a detector saw before (another size, another image).
    small = scene(60, 90)
    first = [linetrack.detect_lines(IMAGE), linetrack.detect_lines(small, scan_interval=1)]
    assert len(first[0]) and len(first[1])
    for k in range(6):  # more settings than are kept: some detectors are made anew
        linetrack.detect_lines(small, max_segments=k + 1)
        linetrack.detect_lines(IMAGE[::2, ::2], scan_interval=1)
        np.testing.assert_array_equal(linetrack.detect_lines(IMAGE), first[0])
        np.testing.assert_array_equal(linetrack.detect_lines(small, scan_interval=1), first[1])


def test_threads_get_the_same_results_as_one_thread():
    # The work runs with the GIL released: calls from several threads at once must not
    # interfere with each other.
    images = [np.roll(IMAGE, k, axis=1) for k in range(8)]
    expected = [linetrack.detect_lines(image) for image in images]
    results = [None] * len(images)

    def work(k):
        for _ in range(20):
            got = linetrack.detect_lines(images[k])
            if results[k] is None or np.array_equal(results[k], got):
                results[k] = got
            else:
                results[k] = "differs"

    threads = [threading.Thread(target=work, args=(k,)) for k in range(len(images))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for got, want in zip(results, expected):
        np.testing.assert_array_equal(got, want)


def test_the_shipped_config_files_load_by_path():
    from conftest import REPO

    shifted = np.roll(IMAGE, -6, axis=1)
    right = linetrack.detect_lines(shifted)
    default = linetrack.match_stereo(IMAGE, shifted, SEGMENTS, right)
    shipped = linetrack.match_stereo(IMAGE, shifted, SEGMENTS, right, config=REPO / "configs/l1-matcher.toml")
    for a, b in zip(shipped, default):
        np.testing.assert_array_equal(a, b)
    paper = REPO / "configs/l1-matcher-paper.toml"
    pairs, costs = linetrack.match_stereo(IMAGE, shifted, SEGMENTS, right, config=paper)
    assert pairs.shape == (len(costs), 2)
