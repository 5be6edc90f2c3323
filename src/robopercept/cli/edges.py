"""``robopercept edges``: the edge map of an image (Canny, Sobel magnitude or LoG)."""

from __future__ import annotations

import argparse
import time

import numpy as np

from robopercept.cli._args import UsageError, flag_errors, image_output, load_gray

__all__ = ["register"]

#: default Canny thresholds, in 8-bit grey levels (scaled to the image's, see --low)
DEFAULT_LOW, DEFAULT_HIGH = 50.0, 150.0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``edges`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "edges",
        help="edge map of an image (Canny, Sobel magnitude or LoG)",
        description="Write an edge map of IMAGE as a PNG.",
    )
    p.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    p.add_argument(
        "-o",
        "--output",
        type=image_output,
        default="edges.png",
        help="output image (default: %(default)s)",
    )
    p.add_argument("--method", choices=("canny", "sobel", "log"), default="canny")
    p.add_argument(
        "--low",
        type=float,
        default=None,
        help="Canny low threshold in the image's grey levels (0..255 for 8-bit, 0..65535 "
        "for 16-bit images; default 50, times 257 for 16-bit images)",
    )
    p.add_argument(
        "--high",
        type=float,
        default=None,
        help="Canny high threshold, as --low (default 150, times 257 for 16-bit images)",
    )
    p.add_argument(
        "--sigma",
        type=float,
        default=1.0,
        help="Gaussian sigma before differentiation (0: none; LoG scale)",
    )
    p.add_argument("--overlay", action="store_true", help="draw edges in red over the image")
    p.set_defaults(func=run_edges)


@flag_errors(sigma="--sigma", low="--low", high="--high")
def run_edges(args: argparse.Namespace) -> int:
    """Run ``robopercept edges`` with the parsed ``args``; returns the exit status."""
    from robopercept.errors import InputError
    from robopercept.imaging import (
        canny,
        gaussian_blur,
        gradient,
        laplacian_of_gaussian,
        log_zero_crossings,
        write_image,
    )
    from robopercept.imaging.edges import grey_level_scale
    from robopercept.viz import draw_mask

    src, gray = load_gray(args.image)
    t0 = time.perf_counter()
    if args.method == "canny":
        low, high = args.low, args.high
        if low is None or high is None:  # the defaults are 8-bit grey levels
            try:
                scale = grey_level_scale(gray.dtype)
            except InputError:
                raise UsageError(
                    f"{src.name} is {gray.dtype}: give --low and --high in its grey levels"
                ) from None
            low = DEFAULT_LOW * scale if low is None else low
            high = DEFAULT_HIGH * scale if high is None else high
            if scale != 1.0:
                print(
                    f"{gray.dtype} image: default Canny thresholds {DEFAULT_LOW:g} and "
                    f"{DEFAULT_HIGH:g} (8-bit grey levels) scaled by {scale:.6g} to its grey "
                    f"levels: --low {low:.6g} --high {high:.6g}"
                )
        edges = canny(gray, low, high, sigma=args.sigma)
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
