"""Shared fixtures: the repository, the real data beside it, the Rust CLI to compare with.

The CLI (`linetrack-match-pair`) is LINETRACK_MATCH_PAIR when set (`cargo xtask python`
sets it), else the first of target/test-release and target/release that holds it; a
missing CLI fails the tests that need it. Real data is read from LINETRACK_MIDDLEBURY_DIR
and LINETRACK_EUROC_DIR, else from ../shared/data beside the repository; tests whose data
is not on the machine are skipped (reported as skipped, as the Rust suite does).
"""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

REPO = Path(__file__).resolve().parents[3]


def data_dir(env, default):
    """The data folder named by `env`, else `default` under ../shared/data."""
    return Path(os.environ.get(env) or REPO.parent / "shared" / "data" / default)


MIDDLEBURY = data_dir("LINETRACK_MIDDLEBURY_DIR", "middlebury")
EUROC = data_dir("LINETRACK_EUROC_DIR", "euroc/V1_01_easy_micro")


def middlebury_pairs():
    """(name, left, right) of every Middlebury pair: 25 scenes of 2005/2006, 3 of 2001-2003."""
    pairs = [
        (d.name, d / "view1.png", d / "view5.png")
        for d in sorted((MIDDLEBURY / "2005-2006-third").glob("*"))
        if (d / "view1.png").is_file()
    ]
    pairs += [
        (d.name, d / "imL.png", d / "imR.png")
        for d in sorted((MIDDLEBURY / "2001-2003").glob("*"))
        if (d / "imL.png").is_file()
    ]
    return pairs


def euroc_frames(camera):
    """The EuRoC excerpt's frames of `camera` (cam0 or cam1), in time order."""
    return sorted((EUROC / "mav0" / camera / "data").glob("*.png"))


def grey(path):
    """An image file as a 2-D uint8 array (colour converted by Pillow)."""
    return np.asarray(Image.open(path).convert("L"))


@pytest.fixture(scope="session")
def match_pair_cli():
    named = os.environ.get("LINETRACK_MATCH_PAIR")
    candidates = [Path(named)] if named else [
        REPO / "target" / profile / "linetrack-match-pair"
        for profile in ("test-release", "release")
    ]
    for path in candidates:
        if path.is_file():
            return path
    pytest.fail(
        "linetrack-match-pair not found at "
        + ", ".join(map(str, candidates))
        + ": build it (cargo build --profile test-release -p linetrack-match-pair) or set "
        "LINETRACK_MATCH_PAIR; `cargo xtask python` does both"
    )


def run_cli(cli, first, second, out_dir, *extra):
    """Runs the CLI with edgelines + l1 on two image files; returns its matches.json."""
    subprocess.run(
        [str(cli), str(first), str(second), "--detector", "edgelines", "--matcher", "l1",
         "--output", str(out_dir), *map(str, extra)],
        check=True,
        capture_output=True,
    )
    return json.loads((out_dir / "matches.json").read_text())


def segments_of(report, key):
    """A CLI report's segments as an (N, 4) float64 array."""
    rows = [[*s["start"], *s["end"]] for s in report[key]]
    return np.array(rows, dtype=np.float64).reshape(-1, 4)
