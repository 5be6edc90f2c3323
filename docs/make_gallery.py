"""Make docs/gallery.md and its pictures, docs/img/gallery/*.png, with the ``robopercept``
commands themselves.

Run from anywhere, with ../shared/data beside the repository (see its SOURCES.md)::

    python docs/make_gallery.py                 # every entry (a few minutes on 2 cores)
    python docs/make_gallery.py --only edges learn   # some commands (the page is rewritten
                                                     # from the whole table either way)

Each entry of :data:`ENTRIES` is one command line: it is run in-process through
``robopercept.cli.main.main`` (so the gallery shows whatever the commands draw today),
from the repository root and with the paths printed in the page, writes its picture
with the command's own output flag (``-o``, ``--image``, ``--overlays``, ``--snapshot``,
``--out``), and the picture is copied to ``docs/img/gallery/<name>.png``, downscaled to
at most 1280 pixels wide. Progress goes to stderr, a summary to stdout; the exit code is
1 when any command failed (each failure is named with the command's last error line).

Only redistributable inputs appear in the committed pictures: from ../shared/data only
files whose licence allows it (Apache-2.0, BSD: OpenCV's samples, PCL's clouds,
CNES/Pandora's Middlebury pair); otherwise pictures bundled with scikit-image, data sets
bundled with scikit-learn, and procedural scenes made by robopercept. These generated
inputs are written to ``build/gallery/inputs/`` (git-ignored) before the commands run;
the commands' other outputs go to ``build/gallery/out/``.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import io
import os
import shlex
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GALLERY = ROOT / "docs" / "img" / "gallery"
PAGE = ROOT / "docs" / "gallery.md"
#: generated inputs and the commands' other outputs (git-ignored), relative to ROOT
INPUTS = "build/gallery/inputs"
OUT = "build/gallery/out"
DATA = "../shared/data"
GAL = "docs/img/gallery"
#: widest picture in the docs (pixels)
MAX_WIDTH = 1280
#: a PNG larger than this is reduced to a 256-colour palette (bytes)
MAX_BYTES = 450_000

__all__ = ["ENTRIES", "NO_PICTURE", "Entry", "main", "markdown", "run_entry"]


@dataclass(frozen=True)
class Entry:
    """One gallery picture: the command line that makes it and what it shows.

    Attributes
    ----------
    name : str
        What the page calls it (``"learn classify"``); the picture is
        ``docs/img/gallery/<name with '-' for spaces>.png``.
    line : str
        The ``robopercept`` arguments as a shell line (split by :func:`shlex.split`),
        paths relative to the repository root.
    produces : str
        The file the command writes that becomes the picture (relative to the root).
    caption : str
        One sentence on what the picture shows.
    inputs : str
        Where the inputs come from and their licence.
    frame : int or None
        When ``produces`` is a video: the frame (0-based) to show.
    enlarge : int
        Show a tiny picture enlarged this many times (nearest neighbour), as the page
        says.
    """

    name: str
    line: str
    produces: str
    caption: str
    inputs: str
    frame: int | None = None
    enlarge: int = 1

    @property
    def args(self) -> list[str]:
        """The arguments as a POSIX shell in the repository root passes them: split, and
        each unquoted pattern (``left*.jpg``) replaced by the sorted paths it matches."""
        out: list[str] = []
        for token in shlex.split(self.line):
            found = sorted(glob.glob(str(ROOT / token))) if glob.has_magic(token) else []
            out += [os.path.relpath(f, ROOT) for f in found] if found else [token]
        return out

    @property
    def command(self) -> str:
        """The top-level command (``"learn"`` for ``"learn classify"``)."""
        return self.args[0]

    @property
    def picture(self) -> str:
        """The picture's file name in docs/img/gallery."""
        return self.name.replace(" ", "-") + ".png"

    def command_line(self) -> str:
        """The command as a user types it."""
        return f"robopercept {self.line}"


_BOX = f"{DATA}/features/opencv_box"
_LEUVEN = f"{DATA}/features/opencv_leuven"
_CHESS = f"{DATA}/calibration/opencv_chessboard_stereo"
_CONES = f"{DATA}/stereo/middlebury2003_cones"
_APACHE_CV = "OpenCV samples (Apache-2.0)"
_SKIMAGE = "scikit-image's bundled pictures (public domain or CC0, as skimage.data says)"
_PROCEDURAL = f"(robopercept.nn.detection.synthetic, backgrounds from {_SKIMAGE})"

#: the gallery: one command line per picture, in the order of the page
ENTRIES: tuple[Entry, ...] = (
    Entry(
        "edges",
        f"edges {_LEUVEN}/leuvenA.jpg --overlay -o {GAL}/edges.png",
        f"{GAL}/edges.png",
        "Canny edges (the default method and thresholds) drawn in red over a street.",
        f"`leuvenA.jpg`, {_APACHE_CV}",
    ),
    Entry(
        "blobs",
        f"blobs {INPUTS}/coins.png --min-area 100 -o {GAL}/blobs.png",
        f"{GAL}/blobs.png",
        "Otsu threshold and connected components of a tray of coins: each blob's box, "
        "centroid and id 1..N in raster order (the ids of the printed table).",
        f"`coins.png` from {_SKIMAGE}",
    ),
    Entry(
        "features",
        f"features {_BOX}/box_in_scene.png --detector sift -o {GAL}/features.png",
        f"{GAL}/features.png",
        "SIFT keypoints of a cluttered desk, each drawn with its scale and orientation.",
        f"`box_in_scene.png`, {_APACHE_CV}",
    ),
    Entry(
        "hog",
        f"hog {INPUTS}/astronaut.png -o {GAL}/hog.png",
        f"{GAL}/hog.png",
        "The histograms of oriented gradients of each 8 x 8 cell, one line per "
        "orientation bin along its edge direction, brighter for stronger gradients.",
        f"`astronaut.png` (NASA) from {_SKIMAGE}",
    ),
    Entry(
        "match",
        f"match {_BOX}/box.png {_BOX}/box_in_scene.png -o {GAL}/match.png",
        f"{GAL}/match.png",
        "SIFT matches of a box and a scene that holds it, the 100 best drawn: RANSAC "
        "inliers in green, outliers in magenta, and the box's border mapped through the "
        "fitted homography (light blue).",
        f"`box.png`, `box_in_scene.png`, {_APACHE_CV}",
    ),
    Entry(
        "stitch",
        f"stitch {_LEUVEN}/leuvenA.jpg {_LEUVEN}/leuvenB.jpg -o {GAL}/stitch.png",
        f"{GAL}/stitch.png",
        "Two views of the same street joined by a RANSAC homography of their SIFT "
        "matches and a feathered blend, in the first view's frame.",
        f"`leuvenA.jpg`, `leuvenB.jpg`, {_APACHE_CV}",
    ),
    Entry(
        "cloud",
        f"cloud {DATA}/pointcloud/pcl_mOSD/test43.pcd --pass-through z:0:1.3 --voxel 0.003 "
        f"--planes 1:0.01 --clusters 0.02:100:25000 -o {OUT}/cloud_segments.ply "
        f"--image {GAL}/cloud.png",
        f"{GAL}/cloud.png",
        "A Kinect scan of objects on a table, cut at 1.3 m and voxel-filtered: the "
        "table's plane found by RANSAC and each object as a Euclidean cluster, one "
        "colour per segment, seen from the sensor.",
        "`test43.pcd` of the modified Object Segmentation Database in PCL's data repository (BSD)",
    ),
    Entry(
        "detect-hog",
        f"detect-hog {INPUTS}/astronaut.png -o {GAL}/detect-hog.png",
        f"{GAL}/detect-hog.png",
        "The bundled HOG + linear SVM face detector at its default threshold (chosen on "
        "a held-out precision/recall curve), each box labelled with its SVM score.",
        f"`astronaut.png` (NASA) from {_SKIMAGE}",
    ),
    Entry(
        "proposals",
        f"proposals {INPUTS}/coffee.png --max 40 -o {GAL}/proposals.png --quiet",
        f"{GAL}/proposals.png",
        "The 40 best-ranked selective-search proposals (fast mode) on a cup of coffee.",
        f"`coffee.png` (Rachel Michetti) from {_SKIMAGE}",
    ),
    Entry(
        "learn cluster",
        f"learn cluster {INPUTS}/wine.csv --label class -k 3 --standardize "
        f"-o {GAL}/learn-cluster.png",
        f"{GAL}/learn-cluster.png",
        "k-means (k = 3) on the 13 standardized features of 178 wines, drawn on the "
        "first two principal components; the adjusted Rand index against the three "
        "cultivars is printed.",
        "scikit-learn's bundled wine data (UCI, CC BY 4.0), written as CSV",
    ),
    Entry(
        "learn classify",
        f"learn classify {INPUTS}/digits.csv --label digit --model svm --standardize "
        f"-o {OUT}/learn-classify",
        f"{OUT}/learn-classify/roc.png",
        "One-vs-rest ROC curves of an RBF SVM on a held-out share of the 8 x 8 digits, "
        "all ten classes in the legend with their AUC (the command also writes "
        "confusion.png, pr.png and report.json).",
        "scikit-learn's bundled digits (UCI, CC BY 4.0), written as CSV",
    ),
    Entry(
        "learn reduce",
        f"learn reduce {INPUTS}/iris.csv --method lda --label species -o {GAL}/learn-reduce.png",
        f"{GAL}/learn-reduce.png",
        "Linear discriminant analysis of the iris flowers to two dimensions, coloured by species.",
        "scikit-learn's bundled iris data (UCI, CC BY 4.0), written as CSV",
    ),
    Entry(
        "nn detect",
        f"nn detect {INPUTS}/shapes.png -o {OUT}/nn-detect --quiet",
        f"{OUT}/nn-detect/shapes.png",
        "The shipped FCOS detector (trained on procedural shapes) on a procedural canvas "
        "it never saw: boxes, class names and scores, drawn at the canvas' 128 x 128 "
        "pixels.",
        f"a procedural canvas {_PROCEDURAL}",
        enlarge=4,
    ),
    Entry(
        "nn segment",
        f"nn segment {INPUTS}/shapes.png -o {OUT}/nn-segment --quiet",
        f"{OUT}/nn-segment/shapes.png",
        "The shipped U-Net's class map over the same canvas, with its legend.",
        f"a procedural canvas {_PROCEDURAL}",
    ),
    Entry(
        "nn pose",
        f"nn pose {INPUTS}/figure.png -o {OUT}/nn-pose --quiet",
        f"{OUT}/nn-pose/figure.png",
        "The shipped HRNet's 16 MPII joints and skeleton on a procedural figure.",
        f"a procedural figure (robopercept.nn.pose.data, backgrounds from {_SKIMAGE})",
    ),
    Entry(
        "nn cloud",
        f"nn cloud {INPUTS}/table.ply --segment -o {OUT}/nn-cloud --quiet",
        f"{OUT}/nn-cloud/table.png",
        "The shipped PointNet's three best classes for a procedural table, its points "
        "coloured by the shipped part segmenter's labels.",
        "a procedural shape (robopercept.nn.cloud.synthetic), written as PLY",
    ),
    Entry(
        "demo",
        f"demo --out {OUT}/demo --max-frames 150 --no-video --quiet",
        f"{OUT}/demo/plane.png",
        "plane.png of the built-in synthetic RGB-D scene: the tracked board plane's "
        "normal angles and distance per frame against the ground truth.",
        "the built-in synthetic scene (seeded)",
    ),
    Entry(
        "plane-track",
        f"plane-track --source {INPUTS}/synth --out {OUT}/plane-track --quiet",
        f"{OUT}/plane-track/tracking.mp4",
        "A frame of tracking.mp4: the green board found by colour and its plane fitted "
        "by RANSAC in the depth, drawn over the colour image.",
        f"a TUM-layout folder written by `robopercept synth-rgbd {INPUTS}/synth "
        "--frames 60 --seed 1 --quiet`",
        frame=40,
    ),
    Entry(
        "bgsub",
        f"bgsub {DATA}/video/opencv_tree/tree.avi --layout panels --snapshot 60 "
        f"-o {OUT}/bgsub.mp4 --quiet",
        f"{OUT}/bgsub_000060.png",
        "Frame 60 of a swaying tree: the foreground overlay with blob boxes, the "
        "per-pixel Gaussian background model and the mask, side by side.",
        f"`tree.avi`, {_APACHE_CV}",
    ),
    Entry(
        "flow",
        f"flow {DATA}/flow/opencv/basketball1.png {DATA}/flow/opencv/basketball2.png "
        f"-o {GAL}/flow.png --quiet",
        f"{GAL}/flow.png",
        "Lucas-Kanade flow of Shi-Tomasi corners between two basketball frames, the "
        "arrows lengthened by the automatic scale (printed) so that small motions show.",
        f"`basketball1.png`, `basketball2.png`, {_APACHE_CV} (Middlebury other-data)",
    ),
    Entry(
        "meanshift",
        f"meanshift {INPUTS}/ball --truth {INPUTS}/ball_groundtruth.txt --snapshot 45 "
        f"-o {OUT}/meanshift.mp4 --quiet",
        f"{OUT}/meanshift_000045.png",
        "Frame 45 of a ball tracked by mean shift on its hue histogram, the first box "
        "taken from the ground truth; the mean IoU against the truth is printed.",
        "a procedural clip: a blue ball moving over scikit-image's `coffee.png`, with its "
        "ground-truth boxes",
    ),
    Entry(
        "track",
        f"track {INPUTS}/discs --min-area 150 --snapshot 80 -o {OUT}/track.mp4 "
        f"--results {OUT}/tracks.txt --quiet",
        f"{OUT}/track_000080.png",
        "Frame 80 (0-based) of discs crossing a textured background: detections from background "
        "subtraction and one Kalman track per disc with its ID.",
        "a procedural clip (robopercept.motion.moving_blobs)",
    ),
    Entry(
        "stereo",
        f"stereo {_CONES}/left.png {_CONES}/right.png --max-disparity 64 -o {GAL}/stereo.png",
        f"{GAL}/stereo.png",
        "SGM disparity of the Middlebury 2003 cones with its colour bar in pixels; "
        "pixels rejected by the left-right check are NaN and drawn apart.",
        "`left.png`, `right.png` of Middlebury 2003 cones as shipped by CNES/Pandora (Apache-2.0)",
    ),
    Entry(
        "calibrate",
        f"calibrate {_CHESS}/left*.jpg --board 9x6 --square 0.025 "
        f"-o {OUT}/camera.json --overlays {OUT}/calibrate --quiet",
        f"{OUT}/calibrate/left01.png",
        "left01.jpg with its detected 9 x 6 chessboard corners, one of the 13 views the "
        "camera was calibrated from.",
        f"`left01.jpg` ... `left14.jpg`, {_APACHE_CV}",
    ),
)

#: commands (and sub-commands) with no picture in the gallery, and why
NO_PICTURE: dict[str, str] = {
    "info": "prints versions and which optional extras work; nothing to draw.",
    "train-hog": "writes a model (.npz) and prints its held-out precision and recall; "
    "its result is shown by `detect-hog` above.",
    "synth-rgbd": "writes a TUM-layout folder of colour and depth frames; its output is "
    "the input of `plane-track` above.",
    "rgbd-import": "converts an RGB-D folder into the layout `plane-track` reads; it "
    "writes files, no picture.",
    "stereo-calibrate": "writes the stereo rig (JSON, OpenCV or ROS YAML) that "
    "`stereo --calib` reads; no picture.",
    "handeye": "writes a transform (JSON or ROS YAML) and prints residuals; no picture.",
    "warmup": "compiles the numba kernels once per install; no output.",
    "batch": "runs another command's job over many inputs on a Dask cluster; its items "
    "are the pictures of `cloud`, `edges`, `features` and `plane-track` above.",
    "learn predict": "writes one prediction per row (CSV) with a model saved by "
    "`learn classify --save`.",
    "nn train": "trains a classifier for minutes; its curves and confusion matrix are in "
    "docs/nn.md (the train forms of nn detect, segment, pose and cloud: "
    "docs/detection.md, docs/segmentation.md, docs/pose.md, docs/pointcloud_dl.md).",
    "nn eval": "scores a trained classifier (a checkpoint of `nn train`) and writes its "
    "confusion matrix.",
    "nn predict": "prints the classes of 8 x 8 digits (the shipped `digits` classifier) or "
    "of images for a checkpoint of `nn train`.",
    "nn summary": "prints a model's layer table.",
    "nn models": "prints the shipped models' cards (training data, inputs, figure); "
    "nothing to draw.",
}


# --- generated inputs ---------------------------------------------------------------


def _write_csv(
    path: Path, x: np.ndarray, names: Sequence[str], label: str, y: Sequence[str]
) -> None:
    rows = [",".join([*names, label])]
    rows += [",".join([*(f"{v:.6g}" for v in row), str(c)]) for row, c in zip(x, y, strict=True)]
    path.write_text("\n".join(rows) + "\n")


def _sklearn_tables(folder: Path) -> None:
    from sklearn import datasets

    wine = datasets.load_wine()
    names = [n.replace("/", "_") for n in wine.feature_names]
    _write_csv(folder / "wine.csv", wine.data, names, "class",
               [wine.target_names[t] for t in wine.target])  # fmt: skip
    iris = datasets.load_iris()
    names = [n.replace(" (cm)", "_cm").replace(" ", "_") for n in iris.feature_names]
    _write_csv(folder / "iris.csv", iris.data, names, "species",
               [iris.target_names[t] for t in iris.target])  # fmt: skip
    digits = datasets.load_digits()
    names = [f"p{i}" for i in range(digits.data.shape[1])]
    _write_csv(folder / "digits.csv", digits.data, names, "digit",
               [str(t) for t in digits.target])  # fmt: skip


def _skimage_pictures(folder: Path) -> None:
    from skimage import data

    from robopercept.imaging import write_image

    for name in ("coins", "astronaut", "coffee"):
        write_image(folder / f"{name}.png", getattr(data, name)())


def _float_to_u8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.round(np.asarray(image, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)


def _procedural_images(folder: Path) -> None:
    from robopercept.nn.cloud.synthetic import procedural_shapes
    from robopercept.nn.pose.data import procedural_pose_set

    from robopercept.imaging import write_image
    from robopercept.nn.detection.synthetic import procedural_detection_set
    from robopercept.pointcloud import PointCloud, write_point_cloud

    shapes = procedural_detection_set(1, size=(128, 128), rng=1)
    write_image(folder / "shapes.png", _float_to_u8(shapes.images[0]))
    figures = procedural_pose_set(1, size=(128, 128), rng=12345)
    write_image(folder / "figure.png", _float_to_u8(figures.images[0]))
    table = procedural_shapes(1, 2048, classes=("table",), rng=1)
    write_point_cloud(folder / "table.ply", PointCloud(table.points[0].astype(np.float64)))


def _fresh(path: Path) -> Path:
    """An empty folder at ``path`` (frames of an earlier run removed)."""
    if path.exists():
        shutil.rmtree(path)
    path.mkdir(parents=True)
    return path


def _motion_clips(folder: Path) -> None:
    from skimage import data

    from robopercept.imaging import write_image
    from robopercept.motion import moving_blobs

    frames, _ = moving_blobs(100, (640, 480), n_blobs=5, radius=(20.0, 28.0), speed=6.0,
                             illumination_drift=0.0, rng=6)  # fmt: skip
    discs = _fresh(folder / "discs")
    for i, f in enumerate(frames):
        write_image(discs / f"{i:06d}.png", f)

    # a ball (blue, shaded) on a path over a coffee photo, and its VOT boxes
    background = data.coffee() / 255.0  # (400, 600, 3)
    ball = _fresh(folder / "ball")
    yy, xx = np.mgrid[0:400, 0:600].astype(np.float64)
    r = 28.0
    boxes = []
    for i in range(60):
        t = i / 59.0
        cx, cy = 90.0 + 420.0 * t, 200.0 + 110.0 * np.sin(2.0 * np.pi * t)
        d2 = (xx - cx) ** 2 + (yy - cy) ** 2
        inside = d2 <= r * r
        shade = 0.75 + 0.25 * np.sqrt(np.clip(1.0 - d2 / (r * r), 0.0, 1.0))
        frame = background.copy()
        colour = np.array([0.1, 0.45, 0.95])
        frame[inside] = shade[inside, None] * colour
        write_image(ball / f"{i:06d}.png", _float_to_u8(frame))
        boxes.append(f"{cx - r:.1f},{cy - r:.1f},{2 * r:.1f},{2 * r:.1f}")
    (folder / "ball_groundtruth.txt").write_text("\n".join(boxes) + "\n")


def _synthetic_rgbd(folder: Path) -> None:
    from robopercept.cli.main import main as robopercept

    target = folder / "synth"
    if target.exists():
        shutil.rmtree(target)  # synth-rgbd writes a new folder
    with contextlib.redirect_stdout(sys.stderr):
        code = robopercept(["synth-rgbd", str(target), "--frames", "60", "--seed", "1", "--quiet"])
    if code != 0:
        raise RuntimeError(f"robopercept synth-rgbd exited with {code}")


#: the inputs each command needs: (files or folders under INPUTS, the function making them)
PREPARE: dict[str, tuple[tuple[str, ...], Callable[[Path], None]]] = {
    "tables": (("wine.csv", "iris.csv", "digits.csv"), _sklearn_tables),
    "skimage": (("coins.png", "astronaut.png", "coffee.png"), _skimage_pictures),
    "procedural": (("shapes.png", "figure.png", "table.ply"), _procedural_images),
    "clips": (("discs", "ball", "ball_groundtruth.txt"), _motion_clips),
    "rgbd": (("synth",), _synthetic_rgbd),
}


def _needs(entry: Entry) -> set[str]:
    """The PREPARE groups whose files ``entry``'s arguments name."""
    named = {a[len(INPUTS) + 1 :].split("/")[0] for a in entry.args if a.startswith(INPUTS + "/")}
    return {group for group, (files, _) in PREPARE.items() if named & set(files)}


# --- running ------------------------------------------------------------------------


def _save_picture(
    source: Path, target: Path, frame: int | None, enlarge: int = 1
) -> tuple[int, int]:
    """Copy ``source`` (an image, or frame ``frame`` of a video) to the PNG ``target``,
    enlarged ``enlarge`` times (nearest neighbour), at most :data:`MAX_WIDTH` wide
    (Lanczos), as a 256-colour palette when larger than :data:`MAX_BYTES`; returns the
    picture's ``(width, height)``."""
    from PIL import Image

    if frame is not None:
        from robopercept.imaging import VideoReader

        with VideoReader(source) as video:
            for i, rgb in enumerate(video):  # noqa: B007  (rgb is the frame after the loop)
                if i == frame:
                    break
            else:
                raise RuntimeError(f"{source} has no frame {frame}")
        picture = Image.fromarray(np.ascontiguousarray(rgb))
    else:
        with Image.open(source) as im:
            picture = im.convert("RGB")
    if enlarge > 1:
        size = (picture.width * enlarge, picture.height * enlarge)
        picture = picture.resize(size, Image.Resampling.NEAREST)
    if picture.width > MAX_WIDTH:
        height = round(picture.height * MAX_WIDTH / picture.width)
        picture = picture.resize((MAX_WIDTH, height), Image.Resampling.LANCZOS)
    buffer = io.BytesIO()
    picture.save(buffer, format="PNG", optimize=True)
    if buffer.tell() > MAX_BYTES:
        buffer = io.BytesIO()
        palette = picture.quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        palette.save(buffer, format="PNG", optimize=True)
    target.write_bytes(buffer.getvalue())
    return picture.size


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else ""


def run_entry(entry: Entry) -> str | None:
    """Run ``entry``'s command from the repository root and put its picture in the
    gallery; returns None, or the reason it failed (the gallery then keeps its earlier
    picture, if any)."""
    target = GALLERY / entry.picture
    backup = target.with_name(target.name + ".old")
    if target.exists():
        target.replace(backup)
    reason: str | None = "interrupted"
    try:
        reason = _run(entry, target)
    finally:
        if backup.exists():
            if reason is None:
                backup.unlink()
            else:  # the earlier picture, not a half-written one
                backup.replace(target)
    return reason


def _run(entry: Entry, target: Path) -> str | None:
    from robopercept.cli.main import main as robopercept

    produced = ROOT / entry.produces
    produced.unlink(missing_ok=True)
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = robopercept(list(entry.args))
    except (Exception, SystemExit) as exc:  # a crash of one command: report, go on
        return f"raised {type(exc).__name__}: {exc}"
    if code != 0:
        return f"exit code {code}: {_last_line(err.getvalue()) or _last_line(out.getvalue())}"
    if not produced.is_file():
        return f"exit code 0 but {entry.produces} was not written"
    try:
        width, height = _save_picture(produced, target, entry.frame, entry.enlarge)
    except Exception as exc:  # an unreadable picture or video
        target.unlink(missing_ok=True)
        return f"cannot read {entry.produces}: {type(exc).__name__}: {exc}"
    size = target.stat().st_size / 1e3
    print(f"  -> {target.relative_to(ROOT)} {width}x{height}, {size:.0f} kB", file=sys.stderr)
    return None


# --- the page -----------------------------------------------------------------------


def markdown() -> str:
    """The text of docs/gallery.md, from :data:`ENTRIES` and :data:`NO_PICTURE`."""
    lines = [
        "# Gallery: one picture per command",
        "",
        "<!-- written by docs/make_gallery.py: edit the table there, not this page -->",
        "",
        "Each picture below was made by the command printed under it, run from the "
        "repository root with the shared data folder beside it (`../shared/data`, see "
        "its SOURCES.md). Inputs under `build/gallery/inputs/` are written by "
        "`python docs/make_gallery.py` first: pictures bundled with scikit-image, data "
        "sets bundled with scikit-learn, and robopercept's procedural scenes. Only "
        "redistributable inputs are used (Apache-2.0 and BSD files of the shared folder, "
        "public-domain and CC0 pictures, CC BY 4.0 tables). Pictures wider than "
        f"{MAX_WIDTH} pixels are downscaled for this page; "
        "`python docs/make_gallery.py [--only COMMAND ...]` makes them again.",
        "",
    ]
    for entry in ENTRIES:
        lines += [
            f"## {entry.name}",
            "",
            f"![{entry.name}](img/gallery/{entry.picture})",
            "",
            "```sh",
            entry.command_line(),
            "```",
            "",
            entry.caption
            + (f" Frame {entry.frame} of `{entry.produces}`." if entry.frame is not None else "")
            + (f" Shown enlarged {entry.enlarge}x." if entry.enlarge > 1 else "")
            + f" Input: {entry.inputs}.",
            "",
        ]
    lines += ["## Commands without a picture", ""]
    lines += [f"- `{name}`: {why}" for name, why in NO_PICTURE.items()]
    return "\n".join(lines) + "\n"


def _selected(only: Sequence[str] | None) -> list[Entry]:
    if not only:
        return list(ENTRIES)
    keys = {o.replace("-", " ") for o in only} | set(only)
    chosen = [e for e in ENTRIES if e.command in keys or e.name in keys or e.picture[:-4] in keys]
    unknown = sorted(
        o for o in only if not any(o in (e.command, e.name, e.picture[:-4]) or
                                   o.replace("-", " ") == e.name for e in ENTRIES)
    )  # fmt: skip
    if unknown:
        raise SystemExit(f"make_gallery: no entry for {', '.join(unknown)} "
                         f"(entries: {', '.join(e.name for e in ENTRIES)})")  # fmt: skip
    return chosen


def main(argv: Sequence[str] | None = None) -> int:
    """Prepare the inputs, run the selected entries, write the page; 1 if any failed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--only",
        nargs="+",
        metavar="CMD",
        help="only these commands or entries (edges learn-reduce)",
    )
    args = parser.parse_args(argv)
    entries = _selected(args.only)
    os.chdir(ROOT)  # the page's paths are relative to the repository root
    if not Path(DATA).is_dir():
        print(f"make_gallery: {Path(DATA).resolve()} is absent: entries that read it fail",
              file=sys.stderr)  # fmt: skip
    GALLERY.mkdir(parents=True, exist_ok=True)
    (ROOT / OUT).mkdir(parents=True, exist_ok=True)
    inputs = ROOT / INPUTS
    inputs.mkdir(parents=True, exist_ok=True)
    failed: dict[str, str] = {}
    groups = sorted(set().union(*(_needs(e) for e in entries)))
    for group in groups:
        print(f"make_gallery: writing inputs ({group}) ...", file=sys.stderr)
        try:
            PREPARE[group][1](inputs)
        except Exception as exc:
            failed[f"inputs {group}"] = f"{type(exc).__name__}: {exc}"
    times: dict[str, float] = {}
    for k, entry in enumerate(entries, 1):
        if any(group in (g.removeprefix("inputs ") for g in failed) for group in _needs(entry)):
            failed[entry.name] = "its inputs could not be written"
            continue
        print(f"make_gallery: [{k}/{len(entries)}] {entry.command_line()}", file=sys.stderr)
        start = time.perf_counter()
        reason = run_entry(entry)
        times[entry.name] = time.perf_counter() - start
        if reason is not None:
            failed[entry.name] = reason
            print(f"  FAILED: {reason}", file=sys.stderr)
    PAGE.write_text(markdown())
    total = sum(p.stat().st_size for p in GALLERY.glob("*.png"))
    done = len(entries) - len([e for e in entries if e.name in failed])
    print(f"make_gallery: {done}/{len(entries)} pictures made in {sum(times.values()):.0f} s; "
          f"docs/img/gallery holds {total / 1e6:.2f} MB; page written to "
          f"{PAGE.relative_to(ROOT)}")  # fmt: skip
    for name, reason in failed.items():
        print(f"FAILED {name}: {reason}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
