"""``robopercept features``: detect keypoints in an image and draw them."""

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
