"""detect_lines against pytlsd (LSD) and OpenCV-contrib's FLD, from Python, on one EuRoC frame.

    python bindings/python/bench/detectors.py [--frame PNG] [--rounds N]

The detectors run interleaved, one call each per round, so a change of machine load during
the run falls on all of them alike; medians over the rounds and their ratios are printed.
Each gets the frame as the 2-D uint8 array it takes (pytlsd a float64 copy, made outside
the timing). FLD has OpenCV's defaults, as in configs/frontend.toml; detect_lines its
defaults (the 100 longest segments, the pipeline's setting) and, for a like-for-like count,
every segment it finds. Needs numpy, Pillow, pytlsd, opencv-contrib-python-headless.
"""

import argparse
import os
import statistics
import time
from pathlib import Path

import cv2
import numpy as np
import pytlsd
from PIL import Image

import linetrack

REPO = Path(__file__).resolve().parents[3]
EUROC = Path(os.environ.get("LINETRACK_EUROC_DIR") or REPO.parent / "shared/data/euroc/V1_01_easy_micro")


def first_euroc_frame():
    """cam0's first frame of the EuRoC excerpt (the one the Rust criterion bench uses)."""
    rows = (EUROC / "mav0/cam0/data.csv").read_text().splitlines()
    name = next(r for r in rows if r and not r.startswith("#")).split(",")[1].strip()
    return EUROC / "mav0/cam0/data" / name


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frame", type=Path, default=None, help="a grey PNG (default: EuRoC cam0's first)")
    parser.add_argument("--rounds", type=int, default=200)
    args = parser.parse_args()
    frame = args.frame or first_euroc_frame()
    image = np.asarray(Image.open(frame).convert("L"))
    as_float = image.astype(np.float64)
    fld = cv2.ximgproc.createFastLineDetector(10, 1.41421356, 50.0, 50.0, 3, False)
    detectors = {
        "edgelines (detect_lines)": lambda: linetrack.detect_lines(image),
        "edgelines, every segment": lambda: linetrack.detect_lines(image, max_segments=1_000_000),
        "FLD (OpenCV contrib)": lambda: fld.detect(image),
        "LSD (pytlsd)": lambda: pytlsd.lsd(as_float),
    }
    counts = {name: 0 if (found := run()) is None else len(found) for name, run in detectors.items()}
    times = {name: [] for name in detectors}
    for _ in range(args.rounds):
        for name, run in detectors.items():
            start = time.perf_counter_ns()
            run()
            times[name].append((time.perf_counter_ns() - start) / 1e6)
    medians = {name: statistics.median(t) for name, t in times.items()}
    ours = medians["edgelines (detect_lines)"]
    print(f"{frame.name} {image.shape[1]}x{image.shape[0]}, {args.rounds} rounds, "
          f"OpenCV {cv2.__version__} ({cv2.getNumThreads()} threads), load {os.getloadavg()[0]:.1f}")
    print(f"{'detector':<28} {'median ms':>10} {'segments':>9} {'÷ detect_lines':>15}")
    for name, median in medians.items():
        print(f"{name:<28} {median:>10.2f} {counts[name]:>9} {median / ours:>14.2f}x")


if __name__ == "__main__":
    main()
