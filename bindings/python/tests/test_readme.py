"""The README's Python example runs as printed (its data path pointed at this machine's
Middlebury folder), prints its counts and writes its picture."""

import os
import re
import subprocess
import sys

import pytest

from conftest import MIDDLEBURY, REPO


def readme_example():
    text = (REPO / "README.md").read_text()
    section = text.split("### From Python", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@pytest.mark.skipif(not MIDDLEBURY.is_dir(), reason=f"no Middlebury data at {MIDDLEBURY}")
def test_the_readme_example_runs(tmp_path):
    code = readme_example().replace("../shared/data/middlebury/", f"{MIDDLEBURY}/")
    assert str(MIDDLEBURY) in code
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        env={**os.environ, "MPLBACKEND": "Agg"},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    counts = re.fullmatch(r"(\d+)\|(\d+) segments, (\d+) matches\n", done.stdout)
    assert counts and int(counts.group(3)) > 10, done.stdout
    assert (tmp_path / "matches.png").stat().st_size > 10_000
