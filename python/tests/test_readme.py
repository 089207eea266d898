"""README's Python example, run as it stands.

The ```python block under README's "Viewer and Python" is extracted and run
in a folder where `splatray terrain` has made the tiles it names, so the
example a user copies cannot drift from the package."""

from __future__ import annotations

import re
import struct
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def readme_example() -> str:
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 1, f"README.md: expected one ```python block, found {len(blocks)}"
    return blocks[0]


def test_readme_python_example_runs(binary: str, tmp_path: Path) -> None:
    code = readme_example()
    # The example names the command that makes its input; run that command.
    made = re.search(r"tiles: (splatray terrain [^\n]*)", code)
    assert made, "README's Python example must say which command makes its tiles"
    args = made.group(1).split()[1:]
    subprocess.run([binary, *args], cwd=tmp_path, check=True, capture_output=True)
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600
    )
    assert run.returncode == 0, f"README's Python example failed:\n{run.stderr}"
    # What it prints: the share of rays that hit (the survey covers the
    # ground under the camera: 0.907 measured), then ids and a normal.
    share = float(run.stdout.split()[0])
    assert share > 0.9, f"README example: only {share} of the rays hit:\n{run.stdout}"
    png = tmp_path / "survey.png"
    assert png.exists(), "README's Python example wrote no survey.png"
    head = png.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n", "survey.png is not a PNG"
    assert struct.unpack(">II", head[16:24]) == (320, 240)
