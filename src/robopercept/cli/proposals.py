"""``robopercept proposals``: selective-search object proposals drawn on an image."""

from __future__ import annotations

import argparse
import json
import sys

from robopercept.cli._args import image_output, positive_int

__all__ = ["register"]

#: outline colours cycled over the proposals by rank (bright on photos)
_PALETTE = (
    (255, 255, 0),
    (0, 255, 255),
    (255, 0, 255),
    (0, 255, 0),
    (255, 128, 0),
    (128, 128, 255),
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``proposals`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "proposals",
        help="selective-search object proposals drawn on an image",
        description="Selective search (Uijlings et al. 2013, as OpenCV's ximgproc): "
        "Felzenszwalb regions grouped by colour, texture, size and fill; draws the best "
        "ranked proposals on IMAGE.",
    )
    p.add_argument("image", help="input image (RGB or gray)")
    p.add_argument(
        "-o", "--output", type=image_output, default=None, help="picture of the proposals"
    )
    p.add_argument(
        "--mode",
        choices=("fast", "quality"),
        default="fast",
        help="diversification: fast (8 groupings) or quality (100, much slower)",
    )
    p.add_argument(
        "--max", type=positive_int, default=200, help="proposals kept, best ranked (default 200)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the ranking (default 0)")
    p.add_argument("--json", action="store_true", help="machine-readable output on stdout")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run_proposals)


def run_proposals(args: argparse.Namespace) -> int:
    """Run ``robopercept proposals`` with the parsed ``args``; returns the exit status."""
    from robopercept.features import selective_search
    from robopercept.imaging import read_image, write_image
    from robopercept.viz import draw_boxes
    from robopercept.viz.draw import to_rgb8

    image = read_image(args.image, mode="rgb")
    boxes = selective_search(
        image, args.mode, rng=args.seed, max_proposals=args.max, progress=not args.quiet
    )
    written = None
    if args.output:
        h, w = image.shape[:2]
        width = max(1, round(max(h, w) / 600))  # 2-3 px on a 1080p picture
        pic = to_rgb8(image)
        for c, color in enumerate(_PALETTE):
            pic = draw_boxes(pic, boxes[c :: len(_PALETTE)], color=color, width=width)
        written = write_image(args.output, pic)
    if args.json:
        json.dump(
            {
                "image": str(args.image),
                "mode": args.mode,
                "max": args.max,
                "seed": args.seed,
                "count": len(boxes),
                "boxes_xywh": boxes.tolist(),
                "picture": None if written is None else str(written),
            },
            sys.stdout,
        )
        print()
        return 0
    print(f"{args.image}: {len(boxes)} proposals ({args.mode} mode, best ranked first)")
    for x, y, bw, bh in boxes[:10].tolist():
        print(f"  x={x} y={y} w={bw} h={bh}")
    if len(boxes) > 10:
        print(f"  ... {len(boxes) - 10} more (--json for all)")
    if args.output:
        print(f"picture -> {args.output}")
    return 0
