"""``robopercept stereo``: disparity (and optionally a point cloud) from a rectified
stereo pair by block matching or semi-global matching."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

from robopercept.cli._args import (
    UsageError,
    cloud_output,
    flag_errors,
    image_output,
    output_path,
    positive_int,
)

if TYPE_CHECKING:
    import numpy as np

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``stereo`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "stereo",
        help="disparity map of a rectified stereo pair (block matching or SGM)",
        description="Match LEFT against RIGHT (rectified: corresponding points share a row) "
        "and write the disparity coloured with Turbo (near red, far blue) with a colour bar; "
        "pixels that fail the left-right consistency check (on by default) are NaN and "
        "drawn apart. --truth evaluates against a ground-truth disparity image; --ply "
        "writes the 3-D points z = f B / d with the left image's colours (disparities of "
        "1 px or less, whose depth is unknown to a factor of two, give no point).",
    )
    p.add_argument("left", help="left image of the rectified pair (the reference view)")
    p.add_argument("right", help="right image of the pair")
    p.add_argument(
        "--method",
        choices=("sgm", "bm"),
        default="sgm",
        help="semi-global matching (smoothness along --paths directions, as OpenCV's SGBM) "
        "or block matching (the best --window match per pixel, as OpenCV's StereoBM)",
    )
    p.add_argument(
        "--max-disparity",
        type=positive_int,
        required=True,
        help="largest disparity d searched (pixels; a point at z has d = f B / z)",
    )
    p.add_argument(
        "--min-disparity",
        type=int,
        default=0,
        help="smallest disparity d searched (pixels; negative for converging cameras)",
    )
    p.add_argument("--window", type=positive_int, default=9, help="bm: odd window side")
    p.add_argument("--cost", choices=("sad", "ssd", "ncc"), default="sad", help="bm cost")
    p.add_argument("--block", type=positive_int, default=5, help="sgm: cost block side")
    p.add_argument("--paths", type=int, choices=(4, 8), default=8, help="sgm directions")
    p.add_argument("--P1", type=float, default=None, help="sgm: small-jump penalty")
    p.add_argument("--P2", type=float, default=None, help="sgm: large-jump penalty")
    p.add_argument("--uniqueness", type=float, default=0.0, help="reject ambiguous (0-1)")
    lr = p.add_mutually_exclusive_group()
    lr.add_argument(
        "--lr-check",
        type=float,
        default=1.0,
        help="left-right consistency check: reject (NaN) a pixel whose match in the right "
        "image does not map back within this many pixels (default 1, as OpenCV's SGBM)",
    )
    lr.add_argument(
        "--no-lr-check",
        dest="lr_check",
        action="store_const",
        const=None,
        help="keep every pixel's best match (dense, occlusions filled with wrong matches)",
    )
    p.add_argument(
        "-o",
        "--output",
        type=image_output,
        default="disparity.png",
        help="the disparity picture with its colour bar (default disparity.png)",
    )
    p.add_argument(
        "--no-colorbar",
        action="store_true",
        help="-o is the bare coloured map, pixel for pixel with LEFT (rejected black)",
    )
    p.add_argument(
        "--npy",
        type=output_path("npy"),
        default=None,
        help="also save the float32 disparity (.npy)",
    )
    p.add_argument("--truth", default=None, help="ground-truth disparity image (0 unknown)")
    p.add_argument("--truth-scale", type=float, default=1.0, help="truth = pixel / scale")
    p.add_argument(
        "--ply",
        type=cloud_output,
        default=None,
        help="also write the points, .ply or .pcd (needs --calib or --focal/--baseline)",
    )
    p.add_argument("--focal", type=float, default=None, help="focal length in pixels")
    p.add_argument("--baseline", type=float, default=None, help="baseline (metres)")
    p.add_argument(
        "--calib",
        default=None,
        help="stereo calibration, JSON or OpenCV YAML, as robopercept stereo-calibrate writes it "
        "(K1 dist1 K2 dist2 R T): "
        "the pair is rectified first and --ply needs no --focal/--baseline",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run_stereo)


@flag_errors(
    max_disparity="--max-disparity",
    min_disparity="--min-disparity",
    window="--window",
    block="--block",
    paths="--paths",
    P1="--P1",
    P2="--P2",
    uniqueness="--uniqueness",
    lr_check="--lr-check",
    focal="--focal",
    baseline="--baseline",
)
def run_stereo(args: argparse.Namespace) -> int:
    """Run ``robopercept stereo`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.depth import bad_pixel_rate, block_matching, semi_global_matching
    from robopercept.errors import DegenerateError, InputError
    from robopercept.imaging import read_image, write_image
    from robopercept.viz import colorize_depth, disparity_picture

    if args.ply and not args.calib and (args.focal is None or args.baseline is None):
        raise UsageError("--ply needs --calib, or --focal (pixels) and --baseline (metres)")
    left = read_image(args.left, mode="rgb")
    right = read_image(args.right, mode="rgb")
    Q = None
    if args.calib:
        left, right, Q = _rectify(args.calib, left, right)
    truth = None
    if args.truth:
        truth = read_image(args.truth, mode="gray").astype(np.float64) / args.truth_scale
        if truth.shape != left.shape[:2]:
            raise InputError(
                f"--truth is {truth.shape[1]}x{truth.shape[0]}, the images "
                f"{left.shape[1]}x{left.shape[0]}: give the ground truth of this pair"
            )
    t0 = time.perf_counter()
    if args.method == "sgm":
        disp = semi_global_matching(
            left, right, args.max_disparity, args.P1, args.P2, args.paths,
            min_disparity=args.min_disparity, block=args.block, uniqueness=args.uniqueness,
            lr_check=args.lr_check,
        )  # fmt: skip
    else:
        disp = block_matching(
            left, right, args.max_disparity, args.window, args.cost,
            min_disparity=args.min_disparity, uniqueness=args.uniqueness,
            lr_check=args.lr_check,
        )  # fmt: skip
    ms = 1000 * (time.perf_counter() - t0)
    if args.no_colorbar:
        shown = np.nan_to_num(disp, nan=0.0)
        picture = colorize_depth(shown, 1e-6, float(args.max_disparity))
    else:
        picture = disparity_picture(
            disp,
            method=args.method,
            min_disparity=args.min_disparity,
            max_disparity=args.max_disparity,
            lr_check=args.lr_check,
        )
    write_image(args.output, picture)
    written = [str(args.output)]
    if args.npy:
        np.save(args.npy, disp)
        written.append(str(args.npy))
    finite = np.isfinite(disp)
    summary: dict = {
        "method": args.method,
        "size": [int(disp.shape[1]), int(disp.shape[0])],
        "disparity_range": [int(args.min_disparity), int(args.max_disparity)],
        "lr_check_px": args.lr_check,
        "uniqueness": args.uniqueness,
        "valid_percent": 100.0 * float(finite.mean()),
        "median_disparity": float(np.nanmedian(disp)) if finite.any() else None,
        "ms": ms,
    }
    if truth is not None:
        known = truth > 0
        summary["truth_known_percent"] = 100.0 * float(known.mean())
        summary["density_percent"] = 100.0 * float((finite & known).sum() / max(known.sum(), 1))
        for t in (1.0, 2.0):
            key = f"bad_{t:g}"
            summary[f"{key}_percent"] = 100 * bad_pixel_rate(disp, truth, t)
            try:
                rate = bad_pixel_rate(disp, truth, t, invalid="ignore")
                summary[f"{key}_valid_percent"] = 100 * rate
            except DegenerateError:
                summary[f"{key}_valid_percent"] = None
    if args.ply:
        npts, zmax = _write_ply(
            Path(args.ply), disp, left, args.focal, args.baseline, Q, args.min_disparity
        )
        summary["points"] = npts
        summary["max_depth"] = zmax
        written.append(str(args.ply))
    summary["outputs"] = written
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    check = "off" if args.lr_check is None else f"{args.lr_check:g} px"
    print(f"method            {args.method} ({ms:.0f} ms), left-right check {check}")
    print(f"valid             {summary['valid_percent']:.1f}% of pixels (the rest NaN: rejected)")
    if truth is not None:
        for k in ("1", "2"):
            valid = summary[f"bad_{k}_valid_percent"]
            print(
                f"vs truth          bad-{k}.0 {summary[f'bad_{k}_percent']:.2f}% of known "
                "pixels (rejected count as bad), "
                + ("no valid pixel" if valid is None else f"{valid:.2f}% of the valid ones")
            )
        print(f"density           {summary['density_percent']:.1f}% of the known pixels valid")
    if args.ply:
        far = "" if summary["max_depth"] is None else f", farthest z {summary['max_depth']:.3g}"
        print(f"points            {summary['points']}{far}")
    print(f"wrote             {', '.join(written)}")
    return 0


def _rectify(path: str, left: np.ndarray, right: np.ndarray) -> tuple:
    """``--calib``: read the stereo calibration and rectify the pair with it."""
    from robopercept.calibration import load_calibration, rectify_pair

    return rectify_pair(left, right, load_calibration(path))


def _write_ply(
    path: Path,
    disp: np.ndarray,
    rgb: np.ndarray,
    focal: float | None,
    baseline: float | None,
    Q: np.ndarray | None = None,
    min_disparity: int = 0,
) -> tuple[int, float | None]:
    """``--ply``: the points of the disparities above max(1 px, --min-disparity) (a
    disparity at the search's lower end is a boundary winner, one at 1 px or less has
    an unknown depth: :func:`~robopercept.depth.disparity_to_points`); returns the
    number of points and the largest z."""
    import numpy as np

    from robopercept.depth import disparity_to_points, reprojection_matrix
    from robopercept.pointcloud import PointCloud, write_point_cloud

    if Q is None:
        assert focal is not None and baseline is not None  # checked with the flags
        Q = reprojection_matrix(focal, baseline, (disp.shape[1], disp.shape[0]))
    pts = disparity_to_points(disp, Q, min_disparity=max(1.0, float(min_disparity)))
    ok = np.isfinite(pts).all(axis=2)
    cloud = PointCloud(pts[ok], colors=rgb[ok].astype(np.float64) / 255.0)
    write_point_cloud(path, cloud)
    return int(ok.sum()), (float(pts[ok][:, 2].max()) if ok.any() else None)
