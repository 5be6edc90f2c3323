"""``robopercept edges``: the edge map of an image (Canny, Sobel magnitude or LoG)."""

from __future__ import annotations

import argparse
import json
import sys
import time

from robopercept.cli._args import UsageError, flag_errors, image_output, load_gray

__all__ = ["register"]

#: default Canny thresholds, in 8-bit grey levels (scaled to the image's, see --low)
DEFAULT_LOW, DEFAULT_HIGH = 50.0, 150.0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``edges`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "edges",
        help="edge map of an image (Canny, Sobel magnitude or LoG)",
        description="Write an edge map of IMAGE as a PNG: Canny edges, the Sobel gradient "
        "magnitude, or the zero crossings of the Laplacian of Gaussian (Marr-Hildreth) kept "
        "by a hysteresis threshold on their slope.",
    )
    p.add_argument("image", nargs="?", help="input image (default: the bundled sample)")
    p.add_argument(
        "-o",
        "--output",
        type=image_output,
        default="edges.png",
        help="output image (default: %(default)s)",
    )
    p.add_argument(
        "--method",
        choices=("canny", "sobel", "log"),
        default="canny",
        help="canny: thin edges by hysteresis between --low and --high; sobel: the gradient "
        "magnitude (edges: pixels above a quarter of its peak); log: Laplacian-of-Gaussian "
        "zero crossings",
    )
    p.add_argument(
        "--low",
        type=float,
        default=None,
        help="Canny low threshold in the image's grey levels (0..255 for 8-bit, 0..65535 "
        "for 16-bit images; default 50, times 257 for 16-bit images). LoG: the low "
        "hysteresis threshold on a zero crossing's slope, in multiples of the mean "
        "absolute LoG response (default 1.5; --low 0 --high 0 keeps every crossing)",
    )
    p.add_argument(
        "--high",
        type=float,
        default=None,
        help="Canny high threshold, as --low (default 150, times 257 for 16-bit images); "
        "LoG: the high slope threshold (default 4)",
    )
    p.add_argument(
        "--sigma",
        type=float,
        default=1.0,
        help="Gaussian sigma of the smoothing before differentiation (canny, sobel; 0: none; "
        "cv2.Canny smooths nothing, as --sigma 0); log: its scale, > 0",
    )
    p.add_argument(
        "--l1-gradient",
        action="store_true",
        help="canny: the L1 gradient norm |gx| + |gy| (cv2.Canny's default) instead of the "
        "L2 norm; --sigma 0 --l1-gradient gives exactly cv2.Canny(image, low, high)",
    )
    p.add_argument("--overlay", action="store_true", help="draw edges in red over the image")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(func=run_edges)


@flag_errors(sigma="--sigma", low="--low", high="--high")
def run_edges(args: argparse.Namespace) -> int:
    """Run ``robopercept edges`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.errors import InputError
    from robopercept.imaging import (
        canny,
        gaussian_blur,
        gradient,
        laplacian_of_gaussian,
        log_zero_crossings,
        write_image,
    )
    from robopercept.imaging.edges import LOG_HIGH, LOG_LOW, grey_level_scale
    from robopercept.viz import draw_mask

    src, gray = load_gray(args.image)
    note = sys.stderr if args.json else sys.stdout
    params: dict = {"sigma": args.sigma}
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
                    f"levels: --low {low:.6g} --high {high:.6g}",
                    file=note,
                )
        edges = canny(gray, low, high, sigma=args.sigma, l2_gradient=not args.l1_gradient)
        out = edges.astype(np.uint8) * 255
        params.update(low=low, high=high, units="grey levels", l2_gradient=not args.l1_gradient)
        what = "edge pixels"
    elif args.method == "sobel":
        work = gaussian_blur(gray.astype(np.float32), args.sigma) if args.sigma > 0 else gray
        mag, _ = gradient(work)
        peak = float(mag.max()) or 1.0
        out = np.round(mag / peak * 255.0).astype(np.uint8)
        edges = mag > 0.25 * peak
        params.update(max_gradient=peak, edge_threshold="0.25 x max gradient")
        what = "pixels above a quarter of the largest gradient"
    else:
        if args.sigma <= 0:
            raise UsageError("--sigma must be > 0 for the LoG method")
        low = LOG_LOW if args.low is None else args.low
        high = LOG_HIGH if args.high is None else args.high
        log = laplacian_of_gaussian(gray, args.sigma, normalized=True)
        edges = log_zero_crossings(log, low, high)
        out = edges.astype(np.uint8) * 255
        params.update(low=low, high=high, units="x mean |LoG|")
        what = "zero-crossing pixels"
    ms = (time.perf_counter() - t0) * 1e3
    if args.overlay:
        out = draw_mask(gray, edges, color=(255, 0, 0), alpha=1.0)
    written = write_image(args.output, out)
    n = int(edges.sum())
    if args.json:
        summary = {
            "image": str(src),
            "size": [int(gray.shape[1]), int(gray.shape[0])],
            "method": args.method,
            "parameters": params,
            "edge_pixels": n,
            "edge_fraction": n / edges.size,
            "ms": ms,
            "outputs": [str(written)],
        }
        print(json.dumps(summary, indent=2))
        return 0
    detail = f"{n} {what} ({100.0 * n / edges.size:.1f}%)"
    if args.method == "sobel":
        detail += f", max gradient {params['max_gradient']:.1f}"
    print(
        f"{args.method} edges of {src.name} ({gray.shape[1]}x{gray.shape[0]}): {detail}, "
        f"{ms:.1f} ms -> {written}"
    )
    return 0
