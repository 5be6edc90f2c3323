"""``robopercept blobs``: connected components of a thresholded image and their features."""

from __future__ import annotations

import argparse
import json
import sys

from robopercept.cli._args import UsageError, image_output, load_gray

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``blobs`` command to the ``robopercept`` subcommand parsers ``sub``."""
    b = sub.add_parser(
        "blobs",
        help="connected components of a thresholded image and their features",
        description="Threshold IMAGE (Otsu unless --threshold), label the "
        "8-connected blobs, drop those under --min-area and print the features of the "
        "rest, numbered 1..N in raster order of their first pixel (the ids drawn on the "
        "-o overlay).",
    )
    b.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    b.add_argument(
        "--threshold",
        type=float,
        default=None,
        help="grey level on the image's scale (0..255 for 8-bit, 0..65535 for 16-bit "
        "images); pixels above it are foreground (default: Otsu)",
    )
    b.add_argument("--invert", action="store_true", help="dark objects on a bright background")
    b.add_argument("--min-area", type=int, default=20, help="drop blobs smaller than this (pixels)")
    b.add_argument(
        "--connectivity",
        type=int,
        choices=(4, 8),
        default=8,
        help="neighbours that join pixels into one blob: 4 (edges) or 8 (edges and corners)",
    )
    b.add_argument("--json", action="store_true", help="machine-readable output on stdout")
    b.add_argument(
        "-o",
        "--output",
        type=image_output,
        default=None,
        help="write an overlay image of the blobs",
    )
    b.set_defaults(func=run_blobs)


def run_blobs(args: argparse.Namespace) -> int:
    """Run ``robopercept blobs`` with the parsed ``args``; returns the exit status."""
    from robopercept.imaging import blob_features, label_components, otsu_threshold, write_image
    from robopercept.viz.segmentation import blob_overlay

    if args.min_area < 0:
        raise UsageError(f"--min-area must be >= 0; got {args.min_area}")
    src, gray = load_gray(args.image)
    thr = otsu_threshold(gray) if args.threshold is None else args.threshold
    mask = gray <= thr if args.invert else gray > thr
    # blobs under --min-area are dropped in the library and the rest numbered 1..N
    labels, _ = label_components(mask, args.connectivity, min_area=args.min_area)
    feats = blob_features(labels)
    records = feats.to_records()
    if args.output:  # the blobs tinted and outlined, the image visible around them
        write_image(args.output, blob_overlay(gray, labels))
    if args.json:
        json.dump(
            {
                "image": str(src),
                "threshold": thr,
                "connectivity": args.connectivity,
                "invert": bool(args.invert),
                "min_area": args.min_area,
                "count": len(records),
                "blobs": records,
                **({"overlay": str(args.output)} if args.output else {}),
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
