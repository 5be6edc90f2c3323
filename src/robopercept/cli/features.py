"""``robopercept features`` (detect keypoints and draw them) and ``robopercept hog``
(the HOG picture of an image)."""

from __future__ import annotations

import argparse
import json
import time

__all__ = ["register"]

DETECTORS = ("harris", "shi-tomasi")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "features",
        help="detect corners (Harris, Shi-Tomasi) and draw them",
        description="Detect keypoints in IMAGE and write a PNG with them drawn; "
        "--json prints them as JSON.",
    )
    p.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    p.add_argument(
        "-o", "--output", default="features.png", help="output PNG (default: %(default)s)"
    )
    p.add_argument("--detector", choices=DETECTORS, default="harris")
    p.add_argument(
        "--max", type=int, default=500, help="at most this many keypoints (default: %(default)s)"
    )
    p.add_argument(
        "--quality",
        type=float,
        default=0.01,
        help="keep responses above this fraction of the strongest (default: %(default)s)",
    )
    p.add_argument(
        "--min-distance",
        type=float,
        default=10.0,
        help="minimum spacing in pixels (default: %(default)s)",
    )
    p.add_argument("--block-size", type=int, default=3, help="window of the structure tensor")
    p.add_argument("--subpixel", action="store_true", help="refine positions to subpixel")
    p.add_argument("--json", action="store_true", help="print the keypoints as JSON on stdout")
    p.set_defaults(func=run_features)

    h = sub.add_parser(
        "hog",
        help="draw the histograms of oriented gradients of an image",
        description="Write the HOG picture of IMAGE (per cell, one line per orientation "
        "bin along its edge direction, brightness = strength) and print the descriptor size.",
    )
    h.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    h.add_argument("-o", "--output", default="hog.png", help="output PNG (default: %(default)s)")
    h.add_argument("--cell", type=int, default=8, help="cell size in pixels (default: 8)")
    h.add_argument("--bins", type=int, default=9, help="orientation bins (default: 9)")
    h.add_argument("--block", type=int, default=2, help="block size in cells (default: 2)")
    h.add_argument("--scale", type=int, default=2, help="picture magnification (default: 2)")
    h.add_argument("--json", action="store_true", help="print sizes and timing as JSON")
    h.set_defaults(func=run_hog)


def run_features(args: argparse.Namespace) -> int:
    from robopercept.cli.imaging import _load_gray
    from robopercept.features import harris_corners
    from robopercept.imaging import write_image
    from robopercept.viz import draw_points

    if args.max < 1:
        raise ValueError(f"--max must be >= 1; got {args.max}")
    src, gray = _load_gray(args.image)
    t0 = time.perf_counter()
    kp = harris_corners(
        gray,
        method=args.detector,
        block_size=args.block_size,
        threshold=args.quality,
        min_distance=args.min_distance,
        max_corners=args.max,
        subpixel=args.subpixel,
    )
    ms = (time.perf_counter() - t0) * 1e3
    written = write_image(args.output, draw_points(gray, kp.xy, color=(255, 0, 0), radius=3))
    if args.json:
        print(
            json.dumps(
                {
                    "image": str(src),
                    "detector": args.detector,
                    "ms": round(ms, 3),
                    "keypoints": [
                        {"x": float(x), "y": float(y), "response": float(r)}
                        for (x, y), r in zip(kp.xy, kp.response, strict=True)
                    ],
                }
            )
        )
    else:
        print(
            f"{args.detector}: {len(kp)} keypoints in {src.name} "
            f"({gray.shape[1]}x{gray.shape[0]}), {ms:.1f} ms -> {written}"
        )
    return 0


def run_hog(args: argparse.Namespace) -> int:
    from robopercept.cli.imaging import _load_gray
    from robopercept.features import cell_histograms, hog
    from robopercept.imaging import write_image
    from robopercept.viz import hog_picture

    src, gray = _load_gray(args.image)
    t0 = time.perf_counter()
    desc = hog(gray, orientations=args.bins, cell_size=args.cell, block_size=args.block)
    ms = (time.perf_counter() - t0) * 1e3
    cells = cell_histograms(gray, args.cell, args.bins)
    written = write_image(args.output, hog_picture(cells, args.cell, scale=args.scale))
    report = {
        "image": str(src),
        "cells": [int(cells.shape[0]), int(cells.shape[1])],
        "descriptor_length": int(desc.shape[0]),
        "ms": round(ms, 3),
        "picture": str(written),
    }
    if args.json:
        print(json.dumps(report))
    else:
        print(
            f"hog: {cells.shape[1]}x{cells.shape[0]} cells of {args.cell} px, {args.bins} bins, "
            f"descriptor of {desc.shape[0]} values in {ms:.1f} ms -> {written}"
        )
    return 0
