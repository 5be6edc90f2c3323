"""Make the pictures of docs/depth.md with ``robopercept stereo``.

Run from the repository root with ../shared/data present::

    python docs/make_depth_pictures.py

The pair is Middlebury 2003 "cones" as shipped by CNES/Pandora (Apache-2.0).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from robopercept.cli.main import main
from robopercept.imaging import read_image
from robopercept.viz import draw_text

ROOT = Path(__file__).resolve().parents[1]
PAIR = ROOT.parent / "shared" / "data" / "stereo" / "middlebury2003_cones"
IMG = ROOT / "docs" / "img"


def main_pictures() -> None:
    from PIL import Image

    tiles = []
    with tempfile.TemporaryDirectory() as tmp:
        runs = [("bm", ["--window", "5"], "block matching 5x5"),
                ("bm", ["--window", "11"], "block matching 11x11"),
                ("bm", ["--window", "21"], "block matching 21x21"),
                ("sgm", [], "semi-global matching")]  # fmt: skip
        for i, (method, extra, title) in enumerate(runs):
            out = Path(tmp) / f"{i}.png"
            code = main(["stereo", str(PAIR / "left.png"), str(PAIR / "right.png"),
                         "--method", method, "--max-disparity", "63", "-o", str(out),
                         *extra])  # fmt: skip
            if code != 0:
                raise SystemExit(f"stereo {method} failed")
            tiles.append(draw_text(read_image(out), title, (5, 5), size=14))
    top = np.concatenate(tiles[:2], axis=1)
    bottom = np.concatenate(tiles[2:], axis=1)
    Image.fromarray(np.concatenate([top, bottom], axis=0)).save(
        IMG / "depth_stereo_windows.jpg", quality=85
    )


if __name__ == "__main__":
    main_pictures()
