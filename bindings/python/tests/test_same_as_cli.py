"""Python and the Rust CLI (`linetrack-match-pair --detector edgelines --matcher l1`) give
the same segments and matches, bit for bit, on real images: every Middlebury pair (stereo),
EuRoC pairs (stereo and frame to frame), and with a matcher config given both ways.

Both sides get the same pixels: the image is made grey once here and written as an 8-bit
grey PNG, which the CLI reads unchanged.
"""

import numpy as np
import pytest
from PIL import Image

import linetrack
from conftest import EUROC, MIDDLEBURY, euroc_frames, grey, middlebury_pairs, run_cli, segments_of


def assert_same(report, first, second, matched, *, check_detection=True):
    """`report` (the CLI's) holds exactly `first`, `second` (float32 from detect_lines) and
    `matched` ((pairs, costs) from match_*)."""
    for key, ours in (("first_segments", first), ("second_segments", second)):
        theirs = segments_of(report, key)
        # The CLI's f64 coordinates are f32 values (the detector's), so nothing is lost in
        # Python's float32 and matching the float32 segments is matching the CLI's.
        assert np.array_equal(theirs.astype(np.float32).astype(np.float64), theirs), key
        assert ours.dtype == np.float32 and ours.shape == theirs.shape, key
        assert np.array_equal(ours.astype(np.float64), theirs), key
    pairs, costs = matched
    cli_pairs = np.array([[m["query"], m["train"]] for m in report["matches"]], dtype=np.int64)
    cli_costs = np.array([m["distance"] for m in report["matches"]], dtype=np.float64)
    assert pairs.dtype == np.int64 and costs.dtype == np.float64
    assert np.array_equal(pairs, cli_pairs.reshape(-1, 2))
    assert np.array_equal(costs, cli_costs)


def grey_files(tmp_path, left, right):
    """The pair as grey arrays and as the grey PNGs the CLI reads."""
    images = [grey(left), grey(right)]
    files = [tmp_path / "first.png", tmp_path / "second.png"]
    for image, file in zip(images, files):
        Image.fromarray(image).save(file)
    return images, files


@pytest.mark.skipif(not MIDDLEBURY.is_dir(), reason=f"no Middlebury data at {MIDDLEBURY}")
@pytest.mark.parametrize("name, left, right", middlebury_pairs(), ids=lambda v: str(v)[-40:])
def test_middlebury_stereo_pair(match_pair_cli, tmp_path, name, left, right):
    (a, b), files = grey_files(tmp_path, left, right)
    report = run_cli(match_pair_cli, *files, tmp_path / "cli")
    first, second = linetrack.detect_lines(a), linetrack.detect_lines(b)
    matched = linetrack.match_stereo(a, b, first, second)
    assert len(first) > 50 and len(matched[0]) > 10, name  # real output, not empty
    assert_same(report, first, second, matched)


@pytest.mark.skipif(not MIDDLEBURY.is_dir(), reason=f"no Middlebury data at {MIDDLEBURY}")
def test_all_28_middlebury_pairs_are_compared():
    assert len(middlebury_pairs()) == 28


@pytest.mark.skipif(not EUROC.is_dir(), reason=f"no EuRoC data at {EUROC}")
@pytest.mark.parametrize("mode", ["stereo", "frame-to-frame"])
def test_euroc_pairs(match_pair_cli, tmp_path, mode):
    cam0, cam1 = euroc_frames("cam0"), euroc_frames("cam1")
    assert len(cam0) >= 3 and len(cam1) >= 3
    for k in range(3):
        first, second = (cam0[k], cam1[k]) if mode == "stereo" else (cam0[k], cam0[k + 1])
        # EuRoC frames are grey PNGs already: both read the files themselves.
        report = run_cli(match_pair_cli, first, second, tmp_path / f"{k}", "--mode", mode)
        a, b = grey(first), grey(second)
        segs = linetrack.detect_lines(a), linetrack.detect_lines(b)
        match = linetrack.match_stereo if mode == "stereo" else linetrack.match_frames
        matched = match(a, b, *segs)
        assert len(matched[0]) > 0
        assert_same(report, *segs, matched)


CHANGES = {"lambda": 0.2, "term_weights": {"angle": 2.0}, "gates": {"max_disparity_px": 60}}


def toml_text(table, prefix=""):
    """`table` ({key: value or {key: value}}) as TOML, its tables under `prefix`."""
    lines = [f"{k} = {v}" for k, v in table.items() if not isinstance(v, dict)]
    for k, sub in table.items():
        if isinstance(sub, dict):
            lines += [f"[{prefix}{k}]"] + [f"{kk} = {vv}" for kk, vv in sub.items()]
    return "\n".join(lines) + "\n"


@pytest.mark.skipif(not MIDDLEBURY.is_dir(), reason=f"no Middlebury data at {MIDDLEBURY}")
def test_a_config_as_dict_and_as_file_is_the_clis_config(match_pair_cli, tmp_path):
    name, left, right = middlebury_pairs()[0]
    (a, b), files = grey_files(tmp_path, left, right)
    frontend = tmp_path / "frontend.toml"
    frontend.write_text("[l1]\n" + toml_text(CHANGES, prefix="l1."))
    report = run_cli(match_pair_cli, *files, tmp_path / "cli", "--config", frontend)
    l1_file = tmp_path / "l1.toml"
    l1_file.write_text(toml_text(CHANGES))
    segs = linetrack.detect_lines(a), linetrack.detect_lines(b)
    by_dict = linetrack.match_stereo(a, b, *segs, config=CHANGES)
    by_file = linetrack.match_stereo(a, b, *segs, config=l1_file)
    by_str = linetrack.match_stereo(a, b, *segs, config=str(l1_file))
    default = linetrack.match_stereo(a, b, *segs)
    assert_same(report, *segs, by_dict)
    for other in (by_file, by_str):
        assert np.array_equal(other[0], by_dict[0]) and np.array_equal(other[1], by_dict[1])
    # The config changed something, or this test would not tell a config from none.
    assert len(default[1]) != len(by_dict[1]) or not np.array_equal(default[1], by_dict[1])
