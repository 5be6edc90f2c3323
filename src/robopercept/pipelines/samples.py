"""Small sample inputs for every command, generated (nothing downloaded): what
``robopercept warmup`` and ``benchmarks/first_use.py`` run the commands on.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["chessboard_views", "make_inputs"]


def chessboard_views(folder: Path, board: tuple[int, int]) -> list[Path]:
    """Three pinhole views (640x480, f = 600 px, 0.5 m away, tilted) of a chessboard of
    3 cm squares with ``board`` = (columns, rows) inner corners, written as PNGs into
    ``folder``; returns their paths."""
    from robopercept.geometry.transforms import rotation_from_rotvec
    from robopercept.imaging import write_image

    cols, rows = board
    square = 0.03
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    rays = np.stack([(u - 320) / 600, (v - 240) / 600, np.ones_like(u)], axis=-1)
    paths = []
    for i, rvec in enumerate(([0.2, 0.1, 0.0], [-0.15, 0.25, 0.1], [0.1, -0.3, -0.05])):
        r = rotation_from_rotvec(np.array(rvec))
        centre = np.array([(cols + 1) * square / 2, (rows + 1) * square / 2, 0.0])
        t = np.array([0.0, 0.0, 0.5]) - r @ centre
        n = r[:, 2]
        s = (n @ t) / (rays @ n)
        b = (rays * s[..., None] - t) @ r  # board-plane coordinates
        ix = np.floor(b[..., 0] / square).astype(int)
        iy = np.floor(b[..., 1] / square).astype(int)
        inside = (ix >= 0) & (ix <= cols) & (iy >= 0) & (iy <= rows)
        img = np.where(inside & ((ix + iy) % 2 == 0), 20, 235).astype(np.uint8)
        path = folder / f"board_{i}.png"
        write_image(path, img)
        paths.append(path)
    return paths


def make_inputs(folder: str | Path) -> dict[str, Path]:
    """Write the tiny inputs the warmup commands read into ``folder``.

    Returns
    -------
    dict
        ``image`` (the sample image, coloured), ``image2`` (the first shifted 6 px right
        and 3 px down), ``left`` and ``right`` (a rectified pair with 4 px disparity),
        ``video`` (8 frames, MP4),
        ``cloud`` (PLY: a floor and two boxes), ``table`` (CSV, 3 classes) and
        ``board0..2`` (chessboard views with 6x4 inner corners).
    """
    from robopercept.imaging import VideoWriter, read_image, sample_image_path, write_image
    from robopercept.pointcloud import PointCloud
    from robopercept.pointcloud.io import write_point_cloud

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    gray = read_image(sample_image_path(), mode="gray")
    g = gray.astype(np.float64)  # a colour version: most users' images are RGB
    image = np.stack([g, 0.6 * g + 60, 255 - 0.8 * g], axis=-1).astype(np.uint8)
    paths = {"image": write_image(out / "image.png", image)}
    paths["image2"] = write_image(out / "image2.png", np.roll(image, (3, 6), axis=(0, 1)))
    paths["left"] = write_image(out / "left.png", gray)
    paths["right"] = write_image(out / "right.png", np.roll(gray, -4, axis=1))
    with VideoWriter(out / "video.mp4", fps=10.0) as video:
        for i in range(8):
            video.write(np.roll(image, (i, 2 * i), axis=(0, 1))[:208, :320])
    paths["video"] = out / "video.mp4"
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(0, 2, (3000, 2)), rng.normal(0, 0.002, 3000)]
    boxes = [rng.uniform(0, 0.2, (400, 3)) + np.array([x, 0.5, 0.05]) for x in (0.3, 1.2)]
    write_point_cloud(out / "cloud.ply", PointCloud(np.vstack([floor, *boxes])))
    paths["cloud"] = out / "cloud.ply"
    x = np.vstack([rng.normal(c, 0.5, (30, 3)) for c in (0.0, 3.0, 6.0)])
    lines = ["a,b,c,label"] + [
        f"{r[0]:.4f},{r[1]:.4f},{r[2]:.4f},{i // 30}" for i, r in enumerate(x)
    ]
    (out / "table.csv").write_text("\n".join(lines) + "\n")
    paths["table"] = out / "table.csv"
    for i, p in enumerate(chessboard_views(out, (6, 4))):
        paths[f"board{i}"] = p
    return paths
