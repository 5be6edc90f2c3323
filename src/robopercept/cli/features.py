"""``robopercept features`` (detect keypoints and draw them), ``robopercept hog`` (the
HOG picture of an image), ``robopercept match`` (SIFT matches and their homography) and
``robopercept stitch`` (a two-image panorama)."""

from __future__ import annotations

import argparse
import json
import time

from robopercept.cli._args import UsageError, flag_errors, image_output, load_gray

__all__ = ["register"]

DETECTORS = ("harris", "shi-tomasi", "sift")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``features``, ``hog``, ``match`` and ``stitch`` commands to the subcommand
    parsers ``sub``."""
    p = sub.add_parser(
        "features",
        help="detect keypoints (Harris, Shi-Tomasi corners, SIFT) and draw them",
        description="Detect keypoints in IMAGE and write a PNG with them drawn; "
        "--json prints them as JSON.",
    )
    p.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    p.add_argument(
        "-o",
        "--output",
        type=image_output,
        default="features.png",
        help="output image (default: %(default)s)",
    )
    p.add_argument(
        "--detector",
        choices=DETECTORS,
        default="harris",
        help="Harris corners (det - k trace^2), Shi-Tomasi corners (the smaller "
        "eigenvalue) or SIFT keypoints (difference-of-Gaussian extrema with scale and "
        "orientation)",
    )
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
    h.add_argument(
        "-o",
        "--output",
        type=image_output,
        default="hog.png",
        help="output image (default: %(default)s)",
    )
    h.add_argument("--cell", type=int, default=8, help="cell size in pixels (default: 8)")
    h.add_argument("--bins", type=int, default=9, help="orientation bins (default: 9)")
    h.add_argument("--block", type=int, default=2, help="block size in cells (default: 2)")
    h.add_argument("--scale", type=int, default=2, help="picture magnification (default: 2)")
    h.add_argument("--json", action="store_true", help="print sizes and timing as JSON")
    h.set_defaults(func=run_hog)

    m = sub.add_parser(
        "match",
        help="match SIFT features of two images and fit a homography",
        description="SIFT in A and B, Lowe's ratio test, RANSAC homography A -> B (fitted "
        "on every match); writes the two images side by side with the best --max-matches "
        "matches (smallest descriptor distance) drawn, inliers in green, outliers in "
        "magenta, and A's border mapped through H onto B (light blue); prints the match "
        "and inlier counts and H.",
    )
    _pair_arguments(m, "matches.png")
    m.add_argument(
        "--max-matches",
        type=int,
        default=100,
        help="draw at most this many matches, the best first; 0 draws all "
        "(default: %(default)s; all matches are used for the fit and counted)",
    )
    m.add_argument("--hide-outliers", action="store_true", help="draw inlier matches only")
    m.add_argument("--json", action="store_true", help="print counts and H as JSON")
    m.set_defaults(func=run_match)

    st = sub.add_parser(
        "stitch",
        help="stitch two overlapping images into a panorama",
        description="SIFT matches, a RANSAC homography and a feathered blend in A's frame.",
    )
    _pair_arguments(st, "panorama.png")
    st.add_argument(
        "--blend",
        choices=("feather", "average", "none"),
        default="feather",
        help="where the images overlap: feather (weights growing from each image's border "
        "inwards), average (equal weights) or none (B covers A)",
    )
    st.add_argument("--json", action="store_true", help="print counts, H and size as JSON")
    st.set_defaults(func=run_stitch)


def _pair_arguments(p: argparse.ArgumentParser, output: str) -> None:
    # the two images, the output picture and the matching options of match / stitch
    p.add_argument("image_a", help="first image, A")
    p.add_argument("image_b", help="second image, B, overlapping A")
    p.add_argument(
        "-o",
        "--output",
        type=image_output,
        default=output,
        help="output image (default: %(default)s)",
    )
    p.add_argument("--ratio", type=float, default=0.8, help="ratio test (default: 0.8)")
    p.add_argument("--threshold", type=float, default=3.0, help="RANSAC pixels (default: 3)")


@flag_errors(
    threshold="--quality",
    block_size="--block-size",
    min_distance="--min-distance",
    max_corners="--max",
    n_features="--max",
)
def run_features(args: argparse.Namespace) -> int:
    """Run ``robopercept features`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.features import harris_corners
    from robopercept.imaging import write_image
    from robopercept.viz import draw_lines, draw_points

    if args.max < 1:
        raise UsageError(f"--max must be >= 1; got {args.max}")
    src, gray = load_gray(args.image)
    t0 = time.perf_counter()
    if args.detector == "sift":
        from robopercept.features import sift

        kp = sift(gray, n_features=args.max).keypoints
    else:
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
    if args.detector == "sift":
        # a circle of the keypoint's size and a radius along its orientation
        pic = gray
        for r in sorted(set(np.clip(np.round(kp.scale / 2), 2, 40).astype(int).tolist())):
            sel = np.clip(np.round(kp.scale / 2), 2, 40).astype(int) == r
            pic = draw_points(pic, kp.xy[sel], color=(255, 0, 0), radius=r)
        tip = (
            kp.xy
            + (np.clip(kp.scale / 2, 2, 40) * [np.cos(kp.orientation), np.sin(kp.orientation)]).T
        )
        pic = draw_lines(pic, np.hstack([kp.xy, tip]), color=(255, 0, 0))
    else:
        pic = draw_points(gray, kp.xy, color=(255, 0, 0), radius=3)
    written = write_image(args.output, pic)
    if args.json:
        print(
            json.dumps(
                {
                    "image": str(src),
                    "detector": args.detector,
                    "ms": round(ms, 3),
                    "keypoints": [
                        {
                            "x": float(x),
                            "y": float(y),
                            "size": float(sz),
                            "angle_deg": None if np.isnan(a) else float(np.degrees(a)),
                            "response": float(r),
                        }
                        for (x, y), sz, a, r in zip(
                            kp.xy, kp.scale, kp.orientation, kp.response, strict=True
                        )
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


@flag_errors(cell_size="--cell", orientations="--bins", block_size="--block", scale="--scale")
def run_hog(args: argparse.Namespace) -> int:
    """Run ``robopercept hog`` with the parsed ``args``; returns the exit status."""
    from robopercept.features import cell_histograms, hog
    from robopercept.imaging import write_image
    from robopercept.viz import hog_picture

    src, gray = load_gray(args.image)
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


def _load_pair(args: argparse.Namespace):
    from robopercept.imaging import read_image

    return read_image(args.image_a, mode="rgb"), read_image(args.image_b, mode="rgb")


@flag_errors(ratio="--ratio", threshold="--threshold", max_matches="--max-matches")
def run_match(args: argparse.Namespace) -> int:
    """Run ``robopercept match`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.features import match_images
    from robopercept.imaging import write_image
    from robopercept.viz.features import matches_picture

    if args.max_matches < 0:
        raise UsageError(f"--max-matches must be >= 0 (0 draws all); got {args.max_matches}")
    a, b = _load_pair(args)
    t0 = time.perf_counter()
    m = match_images(a, b, ratio=args.ratio, threshold=args.threshold)
    ms = (time.perf_counter() - t0) * 1e3
    n = len(m.matches.query_idx)
    inl = np.asarray(m.fit.inliers, bool)
    limit = args.max_matches or None
    shown = n if limit is None else min(limit, n if not args.hide_outliers else int(inl.sum()))
    what = "inliers" if args.hide_outliers else "matches"
    caption = f"{int(inl.sum())} inliers of {n} matches; best {shown} {what} drawn"
    pic = matches_picture(
        a,
        m.xy_a,
        b,
        m.xy_b,
        inliers=inl,
        distance=m.matches.distance,
        homography=m.fit.H,
        max_matches=limit,
        show_outliers=not args.hide_outliers,
        caption=caption,
    )
    written = write_image(args.output, pic.image)
    drawn_in = int(inl[pic.drawn].sum())
    report = {
        "image_a": str(args.image_a),
        "image_b": str(args.image_b),
        "keypoints": [len(m.features_a), len(m.features_b)],
        "matches": n,
        "inliers": m.fit.n_inliers,
        "outliers": n - m.fit.n_inliers,
        "rms_px": round(m.fit.rms, 4),
        "H": np.round(m.fit.H, 8).tolist(),
        "drawn": int(pic.drawn.size),
        "drawn_inliers": drawn_in,
        "drawn_outliers": int(pic.drawn.size) - drawn_in,
        "max_matches": args.max_matches,
        "outline": None if pic.outline is None else np.round(pic.outline, 3).tolist(),
        "ms": round(ms, 1),
        "picture": str(written),
    }
    if args.json:
        print(json.dumps(report))
    else:
        print(
            f"match: {report['keypoints'][0]} / {report['keypoints'][1]} SIFT keypoints, "
            f"{n} matches, {report['inliers']} inliers (rms {m.fit.rms:.2f} px), "
            f"{ms:.0f} ms"
        )
        print(
            f"drawn: {report['drawn']} best matches ({drawn_in} inliers, "
            f"{report['drawn_outliers']} outliers), A's outline on B -> {written}"
        )
        print("H (A -> B) =")
        for row in m.fit.H:
            print("  " + "  ".join(f"{v: .6g}" for v in row))
    return 0


@flag_errors(ratio="--ratio", threshold="--threshold", blend="--blend")
def run_stitch(args: argparse.Namespace) -> int:
    """Run ``robopercept stitch`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.features import stitch
    from robopercept.imaging import write_image

    a, b = _load_pair(args)
    t0 = time.perf_counter()
    p = stitch(a, b, blend=args.blend, ratio=args.ratio, threshold=args.threshold)
    ms = (time.perf_counter() - t0) * 1e3
    written = write_image(args.output, p.image)
    if args.json:
        report = {
            "image_a": str(args.image_a),
            "image_b": str(args.image_b),
            "matches": len(p.match.matches.query_idx),
            "inliers": p.match.fit.n_inliers,
            "rms_px": round(p.match.fit.rms, 4),
            "H": np.round(p.match.fit.H, 8).tolist(),
            "size": [int(p.image.shape[1]), int(p.image.shape[0])],
            "blend": args.blend,
            "ms": round(ms, 1),
            "picture": str(written),
        }
        print(json.dumps(report))
        return 0
    print(
        f"stitch: {p.match.fit.n_inliers} inliers of {len(p.match.matches.query_idx)} "
        f"matches, panorama {p.image.shape[1]}x{p.image.shape[0]}, {ms:.0f} ms -> {written}"
    )
    return 0
