"""``robopercept edges``: the edge map of an image (Canny, Sobel magnitude or LoG)."""

from __future__ import annotations

import argparse
import time

import numpy as np

from robopercept.cli._args import UsageError, load_gray

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``edges`` command to the ``robopercept`` subcommand parsers ``sub``."""
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


def run_edges(args: argparse.Namespace) -> int:
    """Run ``robopercept edges`` with the parsed ``args``; returns the exit status."""
    from robopercept.imaging import (
        canny,
        gaussian_blur,
        gradient,
        laplacian_of_gaussian,
        log_zero_crossings,
        write_image,
    )
    from robopercept.viz import draw_mask

    src, gray = load_gray(args.image)
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
            raise UsageError("--sigma must be > 0 for the LoG method")
        log = laplacian_of_gaussian(gray, args.sigma, normalized=True)
        edges = log_zero_crossings(log, 0.05)
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
