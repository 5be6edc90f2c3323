"""``robopercept edges`` and ``robopercept blobs``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np

__all__ = ["bundled_image", "register"]


def bundled_image() -> Path:
    """Path of the sample image shipped with the package (OpenCV's ``box.png``)."""
    return Path(str(resources.files("robopercept") / "data" / "box.png"))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "edges",
        help="edge map of an image (Canny, Sobel magnitude or LoG)",
        description="Write an edge map of IMAGE as a PNG.",
    )
    p.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    p.add_argument("-o", "--output", default="edges.png", help="output PNG (default: %(default)s)")
    p.add_argument("--method", choices=("canny", "sobel", "log"), default="canny")
    p.add_argument("--low", type=float, default=50.0, help="Canny low threshold (grey levels)")
    p.add_argument("--high", type=float, default=150.0, help="Canny high threshold")
    p.add_argument(
        "--sigma",
        type=float,
        default=1.0,
        help="Gaussian sigma before differentiation (0: none; LoG scale)",
    )
    p.add_argument("--overlay", action="store_true", help="draw edges in red over the image")
    p.set_defaults(func=run_edges)

    b = sub.add_parser(
        "blobs",
        help="connected components of a thresholded image and their features",
        description="Threshold IMAGE (Otsu unless --threshold), label the "
        "8-connected blobs and print their features.",
    )
    b.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    b.add_argument(
        "--threshold",
        type=float,
        default=None,
        help="grey level; pixels above it are foreground (default: Otsu)",
    )
    b.add_argument("--invert", action="store_true", help="dark objects on a bright background")
    b.add_argument("--min-area", type=int, default=20, help="drop blobs smaller than this (pixels)")
    b.add_argument("--connectivity", type=int, choices=(4, 8), default=8)
    b.add_argument("--json", action="store_true", help="machine-readable output on stdout")
    b.add_argument("-o", "--output", default=None, help="write an overlay PNG of the blobs")
    b.set_defaults(func=run_blobs)


def _load_gray(path: str | None) -> tuple[Path, np.ndarray]:
    from robopercept.imaging import read_image

    p = Path(path) if path else bundled_image()
    return p, read_image(p, mode="gray")


def run_edges(args: argparse.Namespace) -> int:
    from robopercept.imaging import (
        canny,
        gaussian_blur,
        gradient,
        laplacian_of_gaussian,
        write_image,
    )
    from robopercept.viz import draw_mask

    src, gray = _load_gray(args.image)
    t0 = time.perf_counter()
    if args.method == "canny":
        edges = canny(gray, args.low, args.high, sigma=args.sigma)
        out = edges.astype(np.uint8) * 255
        n = int(edges.sum())
        detail = f"{n} edge pixels ({100.0 * n / edges.size:.1f}%)"
    elif args.method == "sobel":
        work = gaussian_blur(gray.astype(np.float32), args.sigma) if args.sigma > 0 else gray
        mag, _ = gradient(work)
        peak = float(mag.max()) or 1.0
        out = np.round(mag / peak * 255.0).astype(np.uint8)
        edges = mag > 0.25 * peak
        detail = f"max gradient {peak:.1f}"
    else:
        if args.sigma <= 0:
            raise ValueError("--sigma must be > 0 for the LoG method")
        log = laplacian_of_gaussian(gray, args.sigma, normalized=True)
        # zero crossings of the LoG with enough contrast are the edges
        pos = log > 0
        cross = np.zeros_like(pos)
        cross[:, :-1] |= pos[:, :-1] != pos[:, 1:]
        cross[:-1, :] |= pos[:-1, :] != pos[1:, :]
        contrast = np.abs(log) > 0.05 * float(np.abs(log).max() or 1.0)
        edges = cross & contrast
        out = edges.astype(np.uint8) * 255
        detail = f"{int(edges.sum())} zero-crossing pixels"
    ms = (time.perf_counter() - t0) * 1e3
    if args.overlay:
        out = draw_mask(gray, edges, color=(255, 0, 0), alpha=1.0)
    written = write_image(args.output, out)
    print(
        f"{args.method} edges of {src.name} ({gray.shape[1]}x{gray.shape[0]}): {detail}, "
        f"{ms:.1f} ms -> {written}"
    )
    return 0


def run_blobs(args: argparse.Namespace) -> int:
    from robopercept.imaging import blob_features, label_components, otsu_threshold, write_image
    from robopercept.viz import draw_boxes, label_colors
    from robopercept.viz.draw import to_rgb8

    if args.min_area < 0:
        raise ValueError(f"--min-area must be >= 0; got {args.min_area}")
    src, gray = _load_gray(args.image)
    thr = otsu_threshold(gray) if args.threshold is None else args.threshold
    mask = gray <= thr if args.invert else gray > thr
    labels, _ = label_components(mask, args.connectivity)
    feats = blob_features(labels)
    keep = feats.area >= args.min_area
    records = [r for r, k in zip(feats.to_records(), keep, strict=True) if k]
    if args.output:
        colors = label_colors(labels)
        kept = np.isin(labels, feats.labels[keep])
        overlay = to_rgb8(gray)
        overlay[kept] = colors[kept]
        overlay = draw_boxes(
            overlay,
            feats.bbox[keep],
            color=(255, 255, 0),
            width=1,
            labels=[str(r["label"]) for r in records],
        )
        write_image(args.output, overlay)
    if args.json:
        json.dump(
            {
                "image": str(src),
                "threshold": thr,
                "connectivity": args.connectivity,
                "blobs": records,
            },
            sys.stdout,
            indent=2,
        )
        print()
        return 0
    print(
        f"{src.name}: threshold {thr:g}{' (inverted)' if args.invert else ''}, "
        f"{len(records)} blobs with area >= {args.min_area}"
    )
    header = (
        f"{'label':>5} {'area':>7} {'x':>5} {'y':>5} {'w':>5} {'h':>5} {'cx':>8} {'cy':>8} "
        f"{'h/w':>6} {'perim':>8} {'circ':>5} {'holes':>5}"
    )
    print(header)
    for r in records:
        x, y, w, h = r["bbox"]
        cx, cy = r["centroid"]
        print(
            f"{r['label']:>5} {r['area']:>7} {x:>5} {y:>5} {w:>5} {h:>5} {cx:>8.1f} {cy:>8.1f} "
            f"{r['aspect_ratio']:>6.2f} {r['perimeter']:>8.1f} {r['circularity']:>5.2f} "
            f"{r['holes']:>5}"
        )
    if args.output:
        print(f"overlay -> {args.output}")
    return 0
