"""``robopercept bgsub``, ``flow``, ``meanshift`` and ``track``: motion and tracking on
videos (any file ffmpeg reads) or folders of images (sorted by name).

Every command shows a progress bar, writes an annotated MP4, can save chosen frames as
PNG (``--snapshot N``), and prints a summary. A frame of an image folder that cannot
be read is skipped and counted; a video that cannot be decoded is one error (exit 2).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import deque
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from robopercept.cli._args import positive_int

__all__ = ["register"]

IMAGE_EXTS = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm", ".webp"}
BGSUB_METHODS = ("static", "average", "gaussian", "diff", "diff3")


# ---------------------------------------------------------------- argument types


def _box(text: str) -> tuple[float, float, float, float]:
    parts = text.replace(" ", "").split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects x,y,w,h numbers; got {text!r}") from None
    if len(values) != 4:
        raise argparse.ArgumentTypeError(f"expects x,y,w,h (four numbers); got {text!r}")
    return values  # type: ignore[return-value]


def _noise(text: str) -> str | None:
    if text not in ("median", "open-close", "none"):
        raise argparse.ArgumentTypeError(f"expects median, open-close or none; got {text!r}")
    return None if text == "none" else text


# ---------------------------------------------------------------- frames in and out


class FrameSource:
    """Frames of a video file or an image folder, as RGB uint8, with their index.

    Unreadable images of a folder are skipped and counted in :attr:`skipped` (the
    index still advances, so frame numbers stay those of the files' order).
    """

    def __init__(
        self, path: str, *, fps: float | None = None, max_frames: int | None = None
    ) -> None:
        from robopercept.errors import FileFormatError
        from robopercept.imaging import VideoReader

        self.path = Path(path)
        self.skipped: list[str] = []
        self.max_frames = max_frames
        self._video: Any = None
        if self.path.is_dir():
            self.files = sorted(p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_EXTS)
            if not self.files:
                raise FileFormatError(
                    f"{self.path}: no images ({', '.join(sorted(IMAGE_EXTS))}) in this folder"
                )
            self.fps = fps or 25.0
            total = len(self.files)
        elif self.path.is_file():
            self._video = VideoReader(self.path)
            self.fps = fps or self._video.fps or 25.0
            total = self._video.frame_count
            if total == 0:
                raise FileFormatError(f"{self.path}: the video holds no frame ffmpeg can decode")
        else:
            raise FileFormatError(f"{self.path}: no such file or folder")
        self.total = total if max_frames is None else min(total, max_frames)

    def __len__(self) -> int:
        return self.total

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        from robopercept.errors import FileFormatError
        from robopercept.imaging import read_image

        if self._video is None:
            for i, f in enumerate(self.files[: self.total]):
                try:
                    img = read_image(f, mode="rgb")
                except FileFormatError as exc:
                    self.skipped.append(str(exc).splitlines()[0])
                    continue
                yield i, img
        else:
            for i, frame in enumerate(self._video):  # the count is for the progress bar
                if self.max_frames is not None and i >= self.max_frames:
                    self._video.close()
                    break
                yield i, frame


class Outputs:
    """The annotated video and the ``--snapshot`` PNGs (kept if the run stops early)."""

    def __init__(self, path: str, fps: float, snapshots: list[int] | None) -> None:
        from robopercept.imaging import VideoWriter

        self.path = Path(path)
        self.writer = VideoWriter(self.path, fps=fps)
        self.snapshots = set(snapshots or [])
        self.written: list[str] = []

    def add(self, index: int, picture: np.ndarray) -> None:
        from robopercept.imaging import write_image

        self.writer.write(picture)
        if index in self.snapshots:
            png = self.path.with_name(f"{self.path.stem}_{index:06d}.png")
            write_image(png, picture)
            self.written.append(str(png))

    def close(self) -> None:
        self.writer.close()
        if self.writer.frames_written:
            self.written.insert(0, str(self.path))

    def __enter__(self) -> Outputs:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _text_size(image: np.ndarray) -> int:
    """Caption height in pixels: readable on small frames, and on 1080p ones."""
    return max(12, round(image.shape[0] / 36))


def _progress(source: FrameSource, desc: str, quiet: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=len(source), unit="frame", desc=desc, disable=quiet, file=sys.stderr)


def _common(
    p: argparse.ArgumentParser, default_out: str | None, out_help: str | None = None
) -> None:
    p.add_argument(
        "-o",
        "--output",
        default=default_out,
        help=out_help or "output video (default: %(default)s)",
    )
    p.add_argument("--max-frames", type=positive_int, default=None, help="stop after N frames")
    p.add_argument("--fps", type=float, default=None, help="frame rate of an image folder")
    p.add_argument(
        "--snapshot",
        type=int,
        action="append",
        default=None,
        metavar="N",
        help="also save frame N (0-based) as OUTPUT_<N>.png; repeatable",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _finish(source: FrameSource, outputs: Outputs, frames: int, seconds: float) -> None:
    if source.skipped:
        print(
            f"skipped {len(source.skipped)} unreadable frame(s), first: {source.skipped[0]}",
            file=sys.stderr,
        )
    speed = frames / seconds if seconds > 0 else float("nan")
    print(f"frames            {frames} ({speed:.1f} fps), skipped {len(source.skipped)}")
    print(f"wrote             {', '.join(outputs.written) or 'nothing'}")


# ---------------------------------------------------------------- registration


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bgsub",
        help="background subtraction or frame differencing on a video",
        description="Find moving objects with a background model (static: the first frame "
        "or --reference; average: mean of the first frames; gaussian: per-pixel running "
        "Gaussian) or by differencing (diff: frame n back; diff3: three-frame AND, no "
        "ghosts). Writes the foreground as a red overlay with blob boxes.",
    )
    p.add_argument("video", help="video file or folder of images")
    p.add_argument("--method", choices=BGSUB_METHODS, default="gaussian")
    p.add_argument("--reference", default=None, help="static: image of the empty scene")
    p.add_argument(
        "--threshold", type=float, default=None, help="0-255 (static/average 30, diff 25)"
    )
    p.add_argument("--k", type=float, default=2.5, help="gaussian: threshold in std devs")
    p.add_argument("--learning-rate", type=float, default=0.02, help="gaussian: alpha")
    p.add_argument("--init-frames", type=positive_int, default=20, help="average/gaussian")
    p.add_argument("--n", type=positive_int, default=1, help="diff: frames between the two")
    p.add_argument("--noise", type=_noise, default="median", help="median | open-close | none")
    p.add_argument("--noise-size", type=positive_int, default=3)
    p.add_argument("--min-area", type=positive_int, default=100, help="smallest blob (pixels)")
    p.add_argument("--gray", action="store_true", help="work on gray frames (faster)")
    p.add_argument(
        "--layout",
        choices=("overlay", "panels"),
        default="overlay",
        help="overlay only, or overlay | background | mask side by side",
    )
    p.add_argument("--masks", default=None, help="also write each mask as DIR/NNNNNN.png")
    _common(p, "bgsub.mp4")
    p.set_defaults(func=run_bgsub)

    p = sub.add_parser(
        "flow",
        help="Lucas-Kanade optical flow between two images, or point tracks through a video",
        description="Two images A B: Shi-Tomasi corners of A tracked into B, drawn as arrows "
        "(or, with --dense, the flow on a grid coloured by the HSV wheel), and the motion "
        "classified as translation, rotation or zoom. One video: corners tracked frame to "
        "frame and drawn with their trails; lost corners are replaced.",
    )
    p.add_argument("inputs", nargs="+", help="A B (two images) or VIDEO (file or folder)")
    p.add_argument("--window", type=int, default=21, help="odd window side (default 21)")
    p.add_argument("--levels", type=int, default=3, help="pyramid levels above the image")
    p.add_argument("--max-corners", type=positive_int, default=500)
    p.add_argument("--quality", type=float, default=0.01, help="Shi-Tomasi quality level")
    p.add_argument("--min-distance", type=float, default=7.0, help="corner spacing (px)")
    p.add_argument("--scale", type=float, default=1.0, help="arrow lengthening (two images)")
    p.add_argument("--dense", action="store_true", help="two images: colour-coded grid flow")
    p.add_argument("--step", type=positive_int, default=4, help="--dense: grid step (px)")
    p.add_argument("--trail", type=positive_int, default=15, help="video: trail length")
    p.add_argument("--json", action="store_true", help="two images: print the result as JSON")
    _common(p, None, "output (default: flow.png for two images, flow.mp4 for a video)")
    p.set_defaults(func=run_flow)

    p = sub.add_parser(
        "meanshift",
        help="track a colour region through a video by mean shift (or CamShift)",
        description="Learn the colour histogram of --box in the first frame, then move the "
        "window to the centre of mass of the back-projected likelihood in every frame.",
    )
    p.add_argument("video", help="video file or folder of images")
    p.add_argument("--box", type=_box, required=True, metavar="X,Y,W,H", help="target, frame 0")
    p.add_argument("--feature", choices=("hue", "rgb"), default="hue")
    p.add_argument("--bins", type=positive_int, default=None, help="16 (hue) or 8 (rgb)")
    p.add_argument("--camshift", action="store_true", help="adapt the window size (CamShift)")
    p.add_argument(
        "--plain-histogram",
        action="store_true",
        help="no background weighting (OpenCV's histogram)",
    )
    p.add_argument("--results", default=None, help="CSV of frame,x,y,w,h,similarity")
    _common(p, "meanshift.mp4")
    p.set_defaults(func=run_meanshift)

    p = sub.add_parser(
        "track",
        help="multi-object tracking (Kalman filter per track, Hungarian association)",
        description="Detections come from a MOTChallenge det.txt (--detections) or, "
        "without one, from background subtraction (Gaussian model, blobs of at least "
        "--min-area pixels). Draws each track with its ID and writes the MOTChallenge "
        "results file.",
    )
    p.add_argument("video", help="video file or folder of images (e.g. MOT17 img1/)")
    p.add_argument("--detections", default=None, help="MOTChallenge det.txt (frames from 1)")
    p.add_argument("--min-score", type=float, default=None, help="drop weaker detections")
    p.add_argument("--results", default="tracks.txt", help="MOTChallenge results file")
    p.add_argument("--cost", choices=("iou", "mahalanobis", "euclidean"), default="iou")
    p.add_argument("--gate", type=float, default=None, help="see MultiObjectTracker")
    p.add_argument("--min-hits", type=int, default=3)
    p.add_argument("--max-age", type=int, default=5)
    p.add_argument("--min-area", type=positive_int, default=100, help="no det.txt: blob size")
    p.add_argument("--no-detections", action="store_true", help="do not draw the detections")
    _common(p, "tracks.mp4")
    p.set_defaults(func=run_track)


# ---------------------------------------------------------------- bgsub


def _bg_model(args: argparse.Namespace, first: np.ndarray) -> Any:
    from robopercept.imaging import read_image
    from robopercept.motion import (
        AveragedBackground,
        FrameDifference,
        GaussianBackground,
        StaticBackground,
        ThreeFrameDifference,
    )

    clean = {"noise": args.noise, "noise_size": args.noise_size}
    m = args.method
    if m == "static":
        ref = first if args.reference is None else read_image(args.reference, mode="rgb")
        return StaticBackground(_prepare(ref, args.gray), args.threshold or 30.0, **clean)
    if m == "average":
        return AveragedBackground(args.init_frames, args.threshold or 30.0, **clean)
    if m == "gaussian":
        return GaussianBackground(args.k, args.learning_rate, init_frames=args.init_frames, **clean)
    if m == "diff":
        return FrameDifference(args.n, args.threshold or 25.0, **clean)
    return ThreeFrameDifference(args.threshold or 25.0, **clean)


def _prepare(frame: np.ndarray, gray: bool) -> np.ndarray:
    from robopercept.imaging import rgb_to_gray

    return rgb_to_gray(frame) if gray else frame


def _bg_picture(
    frame: np.ndarray,
    mask: np.ndarray,
    boxes: np.ndarray,
    background: Any,
    layout: str,
    label: str = "background",
) -> np.ndarray:
    from robopercept.viz import draw_boxes, draw_mask, draw_text
    from robopercept.viz.draw import to_rgb8

    over = draw_boxes(draw_mask(frame, mask, color=(255, 0, 0), alpha=0.45), boxes, width=2)
    over = draw_text(over, f"{len(boxes)} blob(s)", (5, 5), size=_text_size(frame))
    if layout == "overlay":
        return over
    if background is None:
        bg = np.zeros_like(over)
    else:
        bg = to_rgb8(np.clip(np.round(np.asarray(background)), 0, 255).astype(np.uint8))
    bg = draw_text(bg, label, (5, 5), size=_text_size(frame))
    mk = draw_text(to_rgb8(mask), "mask", (5, 5), size=_text_size(frame))
    return np.concatenate([over, bg, mk], axis=1)


def run_bgsub(args: argparse.Namespace) -> int:
    from robopercept.imaging import write_image
    from robopercept.motion import detections_from_mask

    source = FrameSource(args.video, fps=args.fps, max_frames=args.max_frames)
    masks_dir = Path(args.masks) if args.masks else None
    if masks_dir is not None:
        masks_dir.mkdir(parents=True, exist_ok=True)
    model: Any = None
    delay = 1 if args.method == "diff3" else 0
    label = {"diff": f"frame t-{args.n}", "diff3": "(no background model)"}.get(
        args.method, "background"
    )
    held: deque[tuple[int, np.ndarray]] = deque()
    fractions: list[float] = []
    blobs = frames = 0
    t0 = time.perf_counter()
    with (
        Outputs(args.output, source.fps, args.snapshot) as out,
        _progress(source, f"bgsub {args.method}", args.quiet) as bar,
    ):

        def emit(index: int, frame: np.ndarray, mask: np.ndarray, background: Any) -> None:
            nonlocal blobs
            det = detections_from_mask(mask, args.min_area)
            blobs += len(det)
            fractions.append(float(mask.mean()))
            out.add(index, _bg_picture(frame, mask, det.boxes, background, args.layout, label))
            if masks_dir is not None:
                write_image(masks_dir / f"{index:06d}.png", mask.astype(np.uint8) * 255)

        for i, frame in source:
            work = _prepare(frame, args.gray)
            if model is None:
                model = _bg_model(args, work)
            background = None if model.background is None else model.background.copy()
            mask = model.apply(work)
            frames += 1
            held.append((i, frame))
            if len(held) > delay:
                j, shown = held.popleft()
                emit(j, shown, mask, background if delay == 0 else None)
            bar.update(1)
        for j, shown in held:  # diff3: the last frame has no later frame to compare
            emit(j, shown, np.zeros(shown.shape[:2], dtype=bool), None)
    seconds = time.perf_counter() - t0
    print(f"method            {args.method}")
    if fractions:
        print(f"foreground        {100 * float(np.mean(fractions)):.2f}% of pixels on average")
        print(f"blobs             {blobs / len(fractions):.2f} per frame (>= {args.min_area} px)")
    _finish(source, out, frames, seconds)
    return 0


# ---------------------------------------------------------------- flow


def _flow_pair(args: argparse.Namespace) -> int:
    import json

    from robopercept.errors import DegenerateError, InputError
    from robopercept.imaging import read_image, write_image
    from robopercept.motion import classify_motion, dense_flow, good_features_to_track, lucas_kanade
    from robopercept.viz import draw_flow, draw_text, flow_to_color, flow_wheel

    a, b = (read_image(p, mode="rgb") for p in args.inputs)
    if a.shape != b.shape:
        raise InputError(
            f"the two images must have the same size; got {a.shape[1]}x{a.shape[0]} and "
            f"{b.shape[1]}x{b.shape[0]}"
        )
    output = Path(args.output or "flow.png")
    lk = {"window": args.window, "levels": args.levels}
    t0 = time.perf_counter()
    if args.dense:
        grid, field, res = dense_flow(a, b, step=args.step, **lk)
        points, vectors = grid.reshape(-1, 2), field.reshape(-1, 2)
        color = flow_to_color(field)
        picture = np.kron(color, np.ones((args.step, args.step, 1), dtype=np.uint8))
        full = np.zeros_like(a)
        h, w = min(picture.shape[0], a.shape[0]), min(picture.shape[1], a.shape[1])
        full[:h, :w] = picture[:h, :w]
        wheel = flow_wheel(min(101, a.shape[0] // 4 * 2 + 1, a.shape[1] // 4 * 2 + 1))
        full[-wheel.shape[0] :, -wheel.shape[1] :] = wheel
        picture = full
    else:
        corners = good_features_to_track(a, args.max_corners, args.quality, args.min_distance)
        res = lucas_kanade(a, b, corners, **lk)
        points, vectors = res.start, np.where(res.status[:, None], res.flow, np.nan)
        picture = draw_flow(a, res.start, res.end, status=res.status, scale=args.scale)
    ms = 1000 * (time.perf_counter() - t0)
    try:
        motion = classify_motion(points, vectors)
        kind = motion.kind
        desc = (
            f"{kind}: translation ({motion.translation[0]:+.2f}, {motion.translation[1]:+.2f}) "
            f"px, rotation {np.degrees(motion.rotation):+.2f} deg, scale {motion.scale:.4f}, "
            f"residual {motion.residual:.2f} px"
        )
    except DegenerateError:
        motion, kind, desc = None, "unknown", "unknown: fewer than 2 tracked points"
    picture = draw_text(picture, desc.split(":")[0], (5, 5), size=_text_size(a))
    write_image(output, picture)
    reasons = np.bincount(res.reason.astype(np.int64), minlength=5)
    summary = {
        "points": len(res),
        "tracked": int(res.status.sum()),
        "aperture": int(reasons[1]),
        "left_image": int(reasons[2]),
        "not_converged": int(reasons[3]),
        "high_residual": int(reasons[4]),
        "median_flow_px": float(np.nanmedian(np.hypot(*vectors.T))) if res.status.any() else None,
        "motion": kind,
        "translation": None if motion is None else motion.translation.tolist(),
        "rotation_deg": None if motion is None else float(np.degrees(motion.rotation)),
        "scale": None if motion is None else motion.scale,
        "ms": ms,
        "output": str(output),
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"points            {summary['points']} ({summary['tracked']} tracked)")
    print(
        f"flagged           aperture {summary['aperture']}, left image "
        f"{summary['left_image']}, not converged {summary['not_converged']}, high residual "
        f"{summary['high_residual']}"
    )
    print(f"motion            {desc}")
    print(f"time              {ms:.1f} ms")
    print(f"wrote             {output}")
    return 0


def _flow_video(args: argparse.Namespace) -> int:
    from robopercept.errors import DegenerateError, InputError
    from robopercept.imaging import rgb_to_gray
    from robopercept.motion import classify_motion, good_features_to_track, lucas_kanade
    from robopercept.viz import draw_text, draw_trails, label_colors

    source = FrameSource(args.inputs[0], fps=args.fps, max_frames=args.max_frames)
    output = args.output or "flow.mp4"
    trails: list[deque[np.ndarray]] = []
    ids = np.zeros(0, dtype=np.int64)
    next_id = 1
    prev: np.ndarray | None = None
    kinds: dict[str, int] = {}
    tracked_counts: list[int] = []
    redetections = frames = 0
    t0 = time.perf_counter()
    with (
        Outputs(output, source.fps, args.snapshot) as out,
        _progress(source, "flow", args.quiet) as bar,
    ):
        for i, frame in source:
            gray = rgb_to_gray(frame)
            kind = "-"
            if prev is not None and prev.shape != gray.shape:
                raise InputError(
                    f"frame {i} is {gray.shape[1]}x{gray.shape[0]}, the previous one "
                    f"{prev.shape[1]}x{prev.shape[0]}: every frame must have one size"
                )
            if prev is not None and trails:
                pts = np.array([t[-1] for t in trails])
                res = lucas_kanade(prev, gray, pts, window=args.window, levels=args.levels)
                try:
                    kind = classify_motion(res.start[res.status], res.flow[res.status]).kind
                except DegenerateError:
                    kind = "unknown"
                kinds[kind] = kinds.get(kind, 0) + 1
                keep = np.flatnonzero(res.status)
                trails = [trails[k] for k in keep]
                ids = ids[keep]
                for t, p in zip(trails, res.end[keep], strict=True):
                    t.append(p)
            if len(trails) < args.max_corners // 2:  # replace lost corners
                new = good_features_to_track(
                    gray, args.max_corners, args.quality, args.min_distance
                )
                if trails:
                    have = np.array([t[-1] for t in trails])
                    d2 = ((new[:, None, :] - have[None, :, :]) ** 2).sum(axis=2).min(axis=1)
                    new = new[d2 >= args.min_distance**2]
                new = new[: max(args.max_corners - len(trails), 0)]
                trails += [deque([p], maxlen=args.trail) for p in new]
                ids = np.r_[ids, np.arange(next_id, next_id + len(new))]
                next_id += len(new)
                redetections += 1
            tracked_counts.append(len(trails))
            picture = draw_trails(frame, [np.array(t) for t in trails], colors=label_colors(ids))
            picture = draw_text(
                picture, f"{len(trails)} points, {kind}", (5, 5), size=_text_size(frame)
            )
            out.add(i, picture)
            prev = gray
            frames += 1
            bar.update(1)
    seconds = time.perf_counter() - t0
    if tracked_counts:
        print(f"points            {np.mean(tracked_counts):.0f} tracked per frame on average")
    print(f"detections        {redetections} (corners re-detected below {args.max_corners // 2})")
    if kinds:
        print("motion            " + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())))
    _finish(source, out, frames, seconds)
    return 0


def run_flow(args: argparse.Namespace) -> int:
    from robopercept.errors import InputError

    if len(args.inputs) == 2:
        return _flow_pair(args)
    if len(args.inputs) == 1:
        return _flow_video(args)
    raise InputError(f"flow takes two images (A B) or one video; got {len(args.inputs)} inputs")


# ---------------------------------------------------------------- meanshift


def run_meanshift(args: argparse.Namespace) -> int:
    from robopercept.tracking import MeanShiftTracker
    from robopercept.viz import draw_boxes, draw_text

    source = FrameSource(args.video, fps=args.fps, max_frames=args.max_frames)
    tracker: MeanShiftTracker | None = None
    rows: list[tuple[int, np.ndarray, float]] = []
    frames = 0
    t0 = time.perf_counter()
    with (
        Outputs(args.output, source.fps, args.snapshot) as out,
        _progress(source, "camshift" if args.camshift else "meanshift", args.quiet) as bar,
    ):
        try:
            for i, frame in source:
                if tracker is None:
                    tracker = MeanShiftTracker(
                        frame,
                        args.box,
                        feature=args.feature,
                        bins=args.bins,
                        adaptive=args.camshift,
                        background_weighting=not args.plain_histogram,
                    )
                    box, similarity = tracker.box.astype(np.float64), 1.0
                else:
                    r = tracker.update(frame)
                    box, similarity = np.asarray(r.box, dtype=np.float64), float(r.similarity)
                rows.append((i, box, similarity))
                picture = draw_boxes(frame, box[None], color=(255, 255, 0), width=2)
                picture = draw_text(
                    picture, f"similarity {similarity:.2f}", (5, 5), size=_text_size(frame)
                )
                out.add(i, picture)
                frames += 1
                bar.update(1)
        finally:  # the boxes so far are kept, also on an error or Ctrl-C
            if args.results and rows:
                _write_boxes_csv(Path(args.results), rows)
                out.written.append(args.results)
    seconds = time.perf_counter() - t0
    if len(rows) > 1:
        sims = np.array([s for _, _, s in rows[1:]])
        print(f"similarity        mean {sims.mean():.3f}, min {sims.min():.3f}")
    _finish(source, out, frames, seconds)
    return 0


def _write_boxes_csv(path: Path, rows: list[tuple[int, np.ndarray, float]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["frame,x,y,w,h,similarity"]
    lines += [f"{i},{b[0]:.2f},{b[1]:.2f},{b[2]:.2f},{b[3]:.2f},{s:.4f}" for i, b, s in rows]
    path.write_text("\n".join(lines) + "\n")


# ---------------------------------------------------------------- track


def run_track(args: argparse.Namespace) -> int:
    from robopercept.motion import GaussianBackground, detections_from_mask
    from robopercept.tracking import MultiObjectTracker, read_mot, write_mot
    from robopercept.viz import draw_boxes, draw_text, label_colors

    det_file = read_mot(args.detections) if args.detections else None
    source = FrameSource(args.video, fps=args.fps, max_frames=args.max_frames)
    tracker = MultiObjectTracker(
        cost=args.cost, gate=args.gate, min_hits=args.min_hits, max_age=args.max_age
    )
    background = None if det_file is not None else GaussianBackground()
    results: list[tuple[int, int, np.ndarray, float]] = []
    ids: set[int] = set()
    n_det = frames = 0
    t0 = time.perf_counter()
    with (
        Outputs(args.output, source.fps, args.snapshot) as out,
        _progress(source, "track", args.quiet) as bar,
    ):
        try:
            for i, frame in source:
                number = i + 1  # MOTChallenge frames count from 1
                if det_file is not None:
                    rows = det_file.at(number)
                    boxes, scores = rows.boxes, rows.conf
                    if args.min_score is not None:
                        keep = scores >= args.min_score
                        boxes, scores = boxes[keep], scores[keep]
                else:
                    assert background is not None
                    det = detections_from_mask(background.apply(frame), args.min_area)
                    boxes, scores = det.boxes, np.ones(len(det))
                n_det += len(boxes)
                tracks = tracker.update(boxes, scores)
                picture = frame
                if not args.no_detections and len(boxes):
                    picture = draw_boxes(picture, boxes, color=(160, 160, 160), width=1)
                for t in tracks:
                    ids.add(t.id)
                    results.append((number, t.id, t.box, t.score))
                    color = tuple(int(c) for c in label_colors(np.array([t.id]))[0])
                    picture = draw_boxes(
                        picture, t.box[None], color=color, width=2, labels=[str(t.id)]
                    )
                picture = draw_text(
                    picture, f"frame {number}: {len(tracks)} track(s)", size=_text_size(frame)
                )
                out.add(i, picture)
                frames += 1
                bar.update(1)
        finally:  # results so far are kept, also on an error or Ctrl-C
            write_mot(args.results, results)
            out.written.append(args.results)
    seconds = time.perf_counter() - t0
    print(f"detections        {n_det} ({n_det / max(frames, 1):.1f} per frame)")
    print(f"tracks            {len(ids)} identities, {len(results)} result rows")
    _finish(source, out, frames, seconds)
    return 0
