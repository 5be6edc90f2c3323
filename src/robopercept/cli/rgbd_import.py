"""``robopercept rgbd-import``: an RGB-D folder of another layout into the tracker's."""

from __future__ import annotations

import argparse
import json
import sys

from robopercept.cli._args import UsageError, numbers

__all__ = ["register", "run_rgbd_import"]

_intrinsics = numbers((float,) * 4, "fx,fy,cx,cy (four numbers, pixels)", ",")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``rgbd-import`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "rgbd-import",
        help="turn an RGB-D folder (TUM lists, color/ + depth/, X_color/X_depth pairs) "
        "into a folder for plane-track",
        description="Read a TUM RGB-D folder (rgb.txt + depth.txt, or an associations.txt "
        "list), color/ (or rgb/) and depth/ subfolders with the same file names, or image "
        "pairs NAME_color.EXT / NAME_depth.EXT (also NAME_rgb, NAME.EXT) and write OUT_DIR "
        "with rgb/, depth/ (16-bit PNG), rgb.txt, depth.txt and camera.json, readable by "
        "`robopercept plane-track --source OUT_DIR`. Depth may be 16-bit PNG, 16-bit PGM, "
        "16-bit or float TIFF; it is taken to be registered to the colour image. The camera "
        "json format is described in docs/tracking.md.",
    )
    p.add_argument("src_dir", metavar="SRC_DIR", help="the RGB-D folder to read")
    p.add_argument("out_dir", metavar="OUT_DIR", help="the folder to write (not SRC_DIR)")
    cam = p.add_mutually_exclusive_group()
    cam.add_argument(
        "--preset",
        choices=("fr1", "fr2", "fr3", "ros-default"),
        help="TUM RGB-D camera: fr1 (517.3, 516.5, 318.6, 255.3 + distortion), fr2 (520.9, "
        "521.0, 325.1, 249.7 + distortion), fr3 (535.4, 539.2, 320.1, 247.6), ros-default "
        "(525, 525, 319.5, 239.5); 640x480 images",
    )
    cam.add_argument(
        "--intrinsics",
        type=_intrinsics,
        metavar="FX,FY,CX,CY",
        help="the camera in pixels (no distortion), for any image size",
    )
    p.add_argument(
        "--depth-scale",
        type=float,
        default=None,
        metavar="UNITS_PER_M",
        help="raw depth units per metre (default 5000 as TUM; 1000 for millimetres); "
        "camera.json stores its inverse, metres per unit",
    )
    p.add_argument(
        "--depth-encoding",
        choices=("linear", "sun", "nyu"),
        default="linear",
        help="linear: metres = value / depth-scale (default); sun: SUN RGB-D's bit-rotated "
        "millimetres; nyu: NYU Depth v2 raw Kinect disparity PGM",
    )
    p.add_argument(
        "--match",
        default=None,
        metavar="PATTERN",
        help="import only pairs named like this (e.g. 'TUM*')",
    )
    p.add_argument(
        "--fps", type=float, default=30.0, help="frame rate for folders without timestamps"
    )
    p.add_argument(
        "--allow-outside-paths",
        action="store_true",
        help="read images that associations.txt, rgb.txt or depth.txt place outside "
        "SRC_DIR (a name with '..' above it, or an absolute path); refused by default, so "
        "that a folder from elsewhere cannot have other files of this machine copied into "
        "OUT_DIR. Give it only for lists you trust",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run_rgbd_import)


def run_rgbd_import(args: argparse.Namespace) -> int:
    """Run ``robopercept rgbd-import`` with the parsed ``args``; returns the exit status."""
    from robopercept.sources import import_rgbd_folder

    if args.preset is None and args.intrinsics is None:
        raise UsageError(
            "rgbd-import needs the camera: --preset fr1|fr2|fr3|ros-default (TUM RGB-D) or "
            "--intrinsics fx,fy,cx,cy"
        )
    res = import_rgbd_folder(
        args.src_dir,
        args.out_dir,
        preset=args.preset,
        intrinsics=args.intrinsics,
        depth_scale=args.depth_scale,
        depth_encoding=args.depth_encoding,
        match=args.match,
        fps=args.fps,
        progress=not (args.quiet or args.json),
        allow_outside=args.allow_outside_paths,
    )
    if args.json:
        report = {
            "src_dir": str(args.src_dir),
            "preset": args.preset,
            "intrinsics": None if args.intrinsics is None else list(args.intrinsics),
            "depth_units_per_m": args.depth_scale,
            "depth_encoding": args.depth_encoding,
            "match": args.match,
            "fps": args.fps,
            **res.to_dict(),
        }
        json.dump(report, sys.stdout, indent=2)
        print()
        return 0
    k = res.camera
    lo, med, hi = res.depth_range_m
    if not args.quiet:
        print(f"layout            {res.layout}")
        print(f"frames            {res.frames} (skipped {len(res.skipped)})")
        print(
            f"camera            {k.width}x{k.height} fx {k.fx:g} fy {k.fy:g} cx {k.cx:g} "
            f"cy {k.cy:g} ({k.model})"
        )
        print(f"depth_scale       {res.depth_scale:g} m per unit (1/{1 / res.depth_scale:g})")
        print(f"first frame depth {lo:.2f} .. {hi:.2f} m, median {med:.2f} m")
        if res.out_of_range:
            print(f"out of range      {res.out_of_range} depth pixels beyond 16 bits set to 0")
    print(
        f"wrote {res.out_dir}/: {', '.join(res.files)}; "
        f"next: robopercept plane-track --source {res.out_dir}"
    )
    return 0
