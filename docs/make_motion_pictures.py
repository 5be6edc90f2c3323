"""Make the pictures of docs/motion.md with the ``robopercept`` commands.

Run from the repository root with ../shared/data present::

    python docs/make_motion_pictures.py

Only redistributable inputs go into the pictures: OpenCV's ``tree.avi`` and
``basketball`` frames (Apache-2.0) and synthetic sequences. PETS 2009, VOT and MOT17
frames carry no licence that allows copying them, so their pictures are made locally
with the commands in docs/motion.md and not committed.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from robopercept.cli.main import main
from robopercept.imaging import read_image, write_image
from robopercept.motion import moving_blobs

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
IMG = ROOT / "docs" / "img"


def _run(*args: str) -> None:
    code = main([*args, "--quiet"])
    if code != 0:
        raise SystemExit(f"robopercept {' '.join(args)} exited with {code}")


def _jpeg(path: Path, image: np.ndarray) -> None:
    from PIL import Image

    Image.fromarray(image).save(path, quality=85)


def _folder(path: Path, frames: np.ndarray) -> Path:
    path.mkdir()
    for i, f in enumerate(frames):
        write_image(path / f"{i:06d}.png", f)
    return path


def _stack(paths: list[Path]) -> np.ndarray:
    return np.concatenate([read_image(p, mode="rgb") for p in paths], axis=0)


def main_pictures() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        # background models on the swaying tree (a dynamic background)
        tree = DATA / "video" / "opencv_tree" / "tree.avi"
        rows = []
        for method in ("gaussian", "diff", "diff3"):
            out = t / f"tree_{method}.mp4"
            _run("bgsub", str(tree), "--method", method, "--layout", "panels",
                 "--snapshot", "40", "-o", str(out))  # fmt: skip
            rows.append(t / f"tree_{method}_000040.png")
        _jpeg(IMG / "motion_bgsub_tree.jpg", _stack(rows))

        # ghosts: moving discs over a texture, the first frame holding the discs
        # (faster than their diameter, so differencing shows a disc and its ghost)
        frames, _ = moving_blobs(40, (160, 120), n_blobs=2, radius=(8.0, 10.0), speed=14.0,
                                 illumination_drift=0.0, rng=4)  # fmt: skip
        seq = _folder(t / "blobs", frames)
        rows = []
        for method in ("static", "gaussian", "diff", "diff3"):
            out = t / f"blobs_{method}.mp4"
            _run("bgsub", str(seq), "--method", method, "--layout", "panels", "--min-area",
                 "30", "--snapshot", "30", "-o", str(out))  # fmt: skip
            rows.append(t / f"blobs_{method}_000030.png")
        write_image(IMG / "motion_bgsub_ghosts.png", _stack(rows))

        # multi-object tracking of the discs (detections from background subtraction)
        frames, _ = moving_blobs(60, (320, 240), n_blobs=4, radius=(12.0, 16.0), speed=3.0,
                                 illumination_drift=0.0, rng=6)  # fmt: skip
        seq = _folder(t / "blobs3", frames)
        _run("track", str(seq), "--min-area", "100", "--snapshot", "50", "-o",
             str(t / "track.mp4"), "--results", str(t / "tracks.txt"))  # fmt: skip
        write_image(IMG / "motion_track.png", read_image(t / "track_000050.png"))

    # Lucas-Kanade between the two basketball frames: arrows, and the colour-coded grid
    a = DATA / "flow" / "opencv" / "basketball1.png"
    b = DATA / "flow" / "opencv" / "basketball2.png"
    _run("flow", str(a), str(b), "--scale", "3", "-o", str(IMG / "motion_flow_arrows.png"))
    _run("flow", str(a), str(b), "--dense", "-o", str(IMG / "motion_flow_dense.png"))
    for name in ("motion_flow_arrows", "motion_flow_dense"):  # keep the repository small
        png = IMG / f"{name}.png"
        _jpeg(IMG / f"{name}.jpg", read_image(png))
        png.unlink()


if __name__ == "__main__":
    main_pictures()
