"""``robopercept learn cluster|classify|predict|reduce`` (CSV tables in, tables, models
and pictures out), ``robopercept detect-hog`` (the HOG + linear SVM face detector) and
``robopercept train-hog`` (rebuild its model)."""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robopercept.cli._args import (
    UsageError,
    file_output,
    flag_errors,
    image_output,
    image_size,
)
from robopercept.errors import InputError

if TYPE_CHECKING:
    import numpy as np

__all__ = ["register"]

CLUSTER_METHODS = ("kmeans", "meanshift", "dbscan")
MODELS = ("tree", "forest", "svm", "lda")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``detect-hog``, ``train-hog``, ``learn``, ``cluster``, ``classify`` and ``reduce``
    commands to the subcommand parsers ``sub``."""
    d = sub.add_parser(
        "detect-hog",
        help="find faces with the HOG + linear SVM sliding-window detector",
        description="Scan IMAGE with the HOG + linear SVM detector (an image pyramid, "
        "non-maximum suppression) and write it with the boxes drawn. The bundled model "
        "finds faces; --model loads one written by `robopercept train-hog`. The default "
        "threshold is the model's own, chosen on a held-out precision/recall curve.",
    )
    d.add_argument("image", help="input image")
    d.add_argument(
        "-o", "--output", type=image_output, default="detections.png", help="output image"
    )
    d.add_argument("--model", help="model .npz (default: the bundled face model)")
    d.add_argument(
        "--threshold",
        type=float,
        default=None,
        help="lowest SVM score (default: the model's, from its held-out PR curve)",
    )
    d.add_argument("--min-size", type=int, help="smallest object in pixels (default: window)")
    d.add_argument("--max-size", type=int, help="largest object in pixels (default: image)")
    d.add_argument("--max", type=int, default=10, help="draw at most this many boxes")
    d.add_argument("--json", action="store_true", help="print the boxes as JSON")
    d.set_defaults(func=run_detect_hog)

    t = sub.add_parser(
        "train-hog",
        help="train a HOG + linear SVM detector (the face model, or your own images)",
        description="Without --positives/--negatives: train the face model on "
        "scikit-image's lfw_subset with hard negatives mined from face-free scikit-image "
        "pictures (needs scikit-image; the defaults rebuild the bundled model exactly). "
        "With --positives DIR --negatives DIR: train on your own images (positives: crops "
        "of the object, each resized to --window; negatives: pictures without it, from "
        "which random windows are cut). A share of the data (--holdout) is never trained "
        "on; the model's default threshold is chosen on its precision/recall curve.",
    )
    t.add_argument("-o", "--output", type=model_output, default="face_hog_svm.npz",
                   help="model file (.npz)")  # fmt: skip
    t.add_argument("--positives", metavar="DIR", help="folder of object crops")
    t.add_argument("--negatives", metavar="DIR", help="folder of pictures without the object")
    t.add_argument(
        "--window",
        type=image_size,
        default=None,
        help="WxH detection window for --positives (default 24x24; whole --cell cells)",
    )
    t.add_argument("--cell", type=int, default=6, help="HOG cell size in pixels (default 6)")
    t.add_argument("--rounds", type=int, default=None,
                   help="hard-negative mining rounds (default 4, with --positives 2)")  # fmt: skip
    t.add_argument("--holdout", type=float, default=0.25,
                   help="share held out for the threshold, 0 to 0.5 (default 0.25)")  # fmt: skip
    t.add_argument("--rule", choices=("f1", "precision"), default="f1",
                   help="threshold: highest F1, or best recall at --min-precision")  # fmt: skip
    t.add_argument("--min-precision", type=float, default=0.95,
                   help="--rule precision: the precision floor (default 0.95)")  # fmt: skip
    t.add_argument(
        "--seed",
        type=int,
        default=0,
        help="the held-out split and the random negative windows",
    )
    t.add_argument("--json", action="store_true", help="print the summary as JSON")
    t.set_defaults(func=run_train_hog)

    learn = sub.add_parser(
        "learn",
        help="cluster, classify, predict or reduce a CSV table",
        description="Classical machine learning on a CSV table with a header row: every "
        "column is a feature except the one named by --label.",
    )
    ls = learn.add_subparsers(dest="learn_command", metavar="TASK", parser_class=type(learn))
    ls.required = True

    c = ls.add_parser(
        "cluster",
        help="k-means, mean-shift or DBSCAN clusters of the rows",
        description="Cluster the rows of DATA; prints the cluster sizes (and the adjusted "
        "Rand index when --label names true classes) and draws the clusters in 2-D (the "
        "two features, or the first two principal components).",
    )
    c.add_argument("data", help="CSV table with a header row")
    c.add_argument(
        "--method",
        choices=CLUSTER_METHODS,
        default="kmeans",
        help="k-means (k = --clusters), mean-shift (--bandwidth) or DBSCAN (--eps, "
        "--min-samples; noise rows get label -1)",
    )
    c.add_argument("--label", help="a column of true classes: left out, and scored by ARI")
    c.add_argument("-k", "--clusters", type=int, default=3, help="k-means: k (default 3)")
    c.add_argument("--bandwidth", type=float, help="mean-shift: bandwidth (default: estimated)")
    c.add_argument("--eps", type=float, default=0.5, help="DBSCAN: radius (default 0.5)")
    c.add_argument("--min-samples", type=int, default=5, help="DBSCAN: core size (default 5)")
    c.add_argument("--standardize", action="store_true", help="scale features to unit variance")
    c.add_argument("--seed", type=int, default=0, help="k-means: the initial centres")
    c.add_argument("-o", "--output", type=image_output, default="clusters.png", help="output image")
    c.add_argument(
        "--labels-out", type=file_output, help="write one cluster label per row to this CSV"
    )
    c.add_argument("--json", action="store_true", help="print the summary as JSON")
    c.set_defaults(func=run_cluster)

    k = ls.add_parser(
        "classify",
        help="train a classifier and report precision, recall, ROC and PR curves",
        description="Train on TRAIN (or on a stratified split of it when no TEST is "
        "given) and report on the test rows: per-class precision, recall, F1, the "
        "confusion matrix, ROC AUC and average precision (one-vs-rest). Writes "
        "confusion.png, roc.png, pr.png and report.json into --output.",
    )
    k.add_argument("train", help="CSV table with a header row: the training rows")
    k.add_argument(
        "test",
        nargs="?",
        help="CSV table of test rows, same columns (default: a stratified --test-size "
        "share of TRAIN)",
    )
    k.add_argument("--label", required=True, help="the column of classes")
    k.add_argument(
        "--model",
        choices=MODELS,
        default="forest",
        help="decision tree (CART), random forest, support vector machine (--kernel, -C) "
        "or linear discriminant analysis",
    )
    k.add_argument("--test-size", type=float, default=0.25, help="held-out share (no TEST)")
    k.add_argument("--cv", type=int, default=0, help="also report k-fold CV accuracy on TRAIN")
    k.add_argument("--max-depth", type=int, help="tree/forest: depth limit")
    k.add_argument("--trees", type=int, default=100, help="forest: trees (default 100)")
    k.add_argument("-C", type=float, default=1.0, help="svm: box constraint (default 1)")
    k.add_argument(
        "--kernel", choices=("rbf", "linear", "poly"), default="rbf", help="svm: the kernel"
    )
    k.add_argument("--standardize", action="store_true", help="scale features (fit on train)")
    k.add_argument("--seed", type=int, default=0, help="the train/test split, the tree and forest")
    k.add_argument("-o", "--output", default="classify_out", help="output folder")
    k.add_argument(
        "--save",
        metavar="MODEL",
        type=model_output,
        help="write the trained model (.npz: arrays and JSON, no pickle) for `learn predict`",
    )
    k.add_argument("--json", action="store_true", help="print the report as JSON")
    k.set_defaults(func=run_classify)

    pr = ls.add_parser(
        "predict",
        help="predict the rows of a CSV table with a model saved by `learn classify --save`",
        description="Load MODEL (written by `learn classify --save`; never unpickled) and "
        "predict every row of DATA, whose columns are taken by name (other columns are "
        "ignored). When DATA has the label column (the training one, or --label), the "
        "accuracy is reported too. Writes one prediction per row to --output.",
    )
    pr.add_argument("model", help="model file (.npz)")
    pr.add_argument("data", help="CSV table with a header row")
    pr.add_argument(
        "--label", help="the column of true classes (default: the model's training label)"
    )
    pr.add_argument(
        "-o", "--output", type=file_output, default="predictions.csv", help="predictions CSV"
    )
    pr.add_argument("--json", action="store_true", help="print the predictions as JSON")
    pr.set_defaults(func=run_predict)

    r = ls.add_parser(
        "reduce",
        help="project the rows to 2-D by PCA or LDA and draw them",
        description="PCA (unsupervised) or LDA (needs --label) to two dimensions; prints "
        "the explained variance of each axis and writes the 2-D scatter, coloured by "
        "--label when given.",
    )
    r.add_argument("data", help="CSV table with a header row")
    r.add_argument(
        "--method",
        choices=("pca", "lda"),
        default="pca",
        help="PCA (largest variance, unsupervised) or LDA (best class separation, needs --label)",
    )
    r.add_argument("--label", help="the column of classes (required by LDA)")
    r.add_argument("--standardize", action="store_true", help="PCA on unit-variance features")
    r.add_argument("-o", "--output", type=image_output, default="reduced.png", help="output image")
    r.add_argument("--transformed", type=file_output, help="write the 2-D coordinates to this CSV")
    r.add_argument("--json", action="store_true", help="print the summary as JSON")
    r.set_defaults(func=run_reduce)


def model_output(text: str) -> str:
    """An output model file: ``.npz``, not a folder (argparse type)."""
    from robopercept._checks import check_extension

    if Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; give a file name ending in .npz")
    try:
        check_extension(text, {".npz"}, "a model file")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


# -- pictures -------------------------------------------------------------------------
def _write(path: str | Path, image: np.ndarray) -> Path:
    from robopercept.imaging import write_image

    return write_image(path, image)


# -- detect-hog / train-hog -----------------------------------------------------------
@flag_errors(threshold="--threshold", min_size="--min-size", max_size="--max-size")
def run_detect_hog(args: argparse.Namespace) -> int:
    """Run ``robopercept detect-hog`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.imaging import read_image
    from robopercept.learning.hog_detector import HogDetector, default_face_detector
    from robopercept.viz import draw_boxes

    image = read_image(args.image, mode="rgb")
    det = HogDetector.load(args.model) if args.model else default_face_detector()
    threshold = det.threshold if args.threshold is None else args.threshold
    t0 = time.perf_counter()
    found = det.detect(
        image,
        threshold=threshold,
        min_size=args.min_size,
        max_size=args.max_size,
        progress=not args.json,
    )
    ms = (time.perf_counter() - t0) * 1e3
    n = min(len(found), max(args.max, 0))
    boxes, scores = found.boxes[:n], found.scores[:n]
    labels = [f"{s:.2f}" for s in scores]
    pic = draw_boxes(image, boxes, color=(0, 255, 0), width=3, labels=labels)
    written = _write(args.output, pic)
    rows = [
        dict(zip(("x", "y", "size"), np.round(b[:3], 1).tolist(), strict=True), score=round(s, 4))
        for b, s in zip(boxes, scores.tolist(), strict=True)
    ]
    if args.json:
        report = {
            "command": "detect-hog",
            "image": args.image,
            "model": args.model or "bundled",
            "threshold": round(float(threshold), 6),
            "threshold_source": "model" if args.threshold is None else "--threshold",
            "found": len(found),
            "ms": round(ms, 1),
            "detections": [
                {**r, "w": round(float(b[2]), 1), "h": round(float(b[3]), 1)}
                for r, b in zip(rows, boxes, strict=True)
            ],
            "output": str(written),
        }
        print(json.dumps(report))
    else:
        source = "the model's" if args.threshold is None else "--threshold"
        print(f"detect-hog: {len(found)} boxes above {threshold:.3f} ({source}) in {ms:.0f} ms")
        for r in rows:
            print(
                f"  x {r['x']:7.1f}  y {r['y']:7.1f}  size {r['size']:6.1f}  score {r['score']:.3f}"
            )
        print(f"-> {written}")
    return 0


@flag_errors(
    holdout="--holdout",
    min_precision="--min-precision",
    cell_size="--cell",
    window="--window",
    mining_rounds="--rounds",
)
def run_train_hog(args: argparse.Namespace) -> int:
    """Run ``robopercept train-hog`` with the parsed ``args``; returns the exit status."""
    from robopercept.learning.hog_detector import (
        train_detector_from_folders,
        train_face_detector,
    )

    if (args.positives is None) != (args.negatives is None):
        raise UsageError("--positives and --negatives go together: give both folders")
    own = args.positives is not None
    rounds = (2 if own else 4) if args.rounds is None else args.rounds
    if rounds < 0:
        raise UsageError(f"--rounds must be >= 0; got {rounds}")
    if not 0.0 <= args.holdout <= 0.5:
        raise UsageError(f"--holdout must be in [0, 0.5]; got {args.holdout}")
    if not 0.0 < args.min_precision <= 1.0:
        raise UsageError(f"--min-precision must be in (0, 1]; got {args.min_precision}")
    if not own and (args.window is not None or args.cell != 6):
        raise UsageError("--window and --cell apply to --positives/--negatives training")
    common = {"holdout": args.holdout, "rule": args.rule, "min_precision": args.min_precision,
              "random_state": args.seed, "progress": not args.json}  # fmt: skip
    t0 = time.perf_counter()
    if own:
        det, report = train_detector_from_folders(
            args.positives, args.negatives, window=args.window or (24, 24),
            cell_size=args.cell, mining_rounds=rounds, **common,
        )  # fmt: skip
        data = {"positives": args.positives, "negatives": args.negatives}
    else:
        det, report = train_face_detector(mining_rounds=rounds, **common)
        data = {"positives": "skimage lfw_subset", "negatives": "skimage pictures"}
    det.save(args.output)
    seconds = time.perf_counter() - t0
    weights = 0 if det.coef_ is None else int(det.coef_.size)
    choice = report.get("choice")
    held = (
        {
            "precision": round(choice.precision, 4),
            "recall": round(choice.recall, 4),
            "f1": round(choice.f1, 4),
            "positives": choice.n_positive,
            "negatives": choice.n_negative,
        }
        if choice is not None
        else None
    )
    if args.json:
        out = {
            "command": "train-hog",
            "output": args.output,
            **data,
            "rounds": rounds,
            "seed": args.seed,
            "window": list(det.window),
            "weights": weights,
            "threshold": round(det.threshold, 6),
            "rule": args.rule,
            "min_precision": args.min_precision if args.rule == "precision" else None,
            "holdout": args.holdout,
            "heldout": held,
            "seconds": round(seconds, 2),
        }
        if own:
            out["images"] = {"positives": report["positives"], "negatives": report["negatives"]}
            out["skipped"] = report["skipped"]
        else:
            out["cv"] = {k: round(float(report[k]), 4) for k in ("accuracy", "precision", "recall")}
        print(json.dumps(out))
        return 0
    if own:
        print(
            f"train-hog: {report['positives']} positives, {report['negatives']} negative "
            f"pictures ({len(report['skipped'])} unreadable files skipped)"
        )
        for line in report["skipped"][:5]:
            print(f"  skipped {line}", file=sys.stderr)
    else:
        print(
            f"train-hog: lfw_subset 5-fold CV accuracy {report['accuracy']:.3f}, precision "
            f"{report['precision']:.3f}, recall {report['recall']:.3f}"
        )
    if held is None:
        print("threshold 0 (--holdout 0: nothing held out to choose it on)")
    else:
        print(
            f"threshold {det.threshold:.3f} ({args.rule} on {held['positives']} held-out "
            f"positives, {held['negatives']} negatives): precision {held['precision']:.3f}, "
            f"recall {held['recall']:.3f}, F1 {held['f1']:.3f}"
        )
    print(f"{weights} weights, {seconds:.1f} s -> {args.output}")
    return 0


# -- learn cluster --------------------------------------------------------------------
def _to_2d(X: np.ndarray, names: Sequence[str]) -> tuple[np.ndarray, str, tuple[str, str]]:
    """The points drawn for ``X``, what they are, and the two axis labels."""
    import numpy as np

    from robopercept.learning import PCA

    if X.shape[1] == 1:
        return np.c_[X[:, 0], np.zeros(len(X))], "feature", (str(names[0]), "")
    if X.shape[1] == 2:
        return X, "the two features", (str(names[0]), str(names[1]))
    return PCA(2).fit_transform(X), "first two principal components", ("PC1", "PC2")


@flag_errors(
    n_clusters="--clusters",
    bandwidth="--bandwidth",
    eps="--eps",
    min_samples="--min-samples",
)
def run_cluster(args: argparse.Namespace) -> int:
    """Run ``robopercept cluster`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.learning import (
        DBSCAN,
        KMeans,
        MeanShift,
        adjusted_rand_score,
        read_table,
        standardize,
    )

    X, y, names = read_table(args.data, args.label)
    if args.standardize:
        (X,) = standardize(X)
    if args.method == "kmeans":
        model: Any = KMeans(args.clusters, random_state=args.seed)
    elif args.method == "meanshift":
        model = MeanShift(bandwidth=args.bandwidth)
    else:
        model = DBSCAN(eps=args.eps, min_samples=args.min_samples)
    t0 = time.perf_counter()
    labels = model.fit(X).labels_
    ms = (time.perf_counter() - t0) * 1e3
    ids, sizes = np.unique(labels[labels >= 0], return_counts=True)
    report: dict[str, Any] = {
        "data": args.data,
        "rows": len(X),
        "features": names,
        "method": args.method,
        "clusters": int(ids.size),
        "sizes": {int(i): int(s) for i, s in zip(ids, sizes, strict=True)},
        "noise": int(np.sum(labels < 0)),
        "ms": round(ms, 1),
    }
    if args.method == "kmeans":
        report["inertia"] = float(model.inertia_)
    if args.method == "meanshift":
        report["bandwidth"] = float(model.bandwidth_)
    if y is not None:
        report["adjusted_rand_index"] = adjusted_rand_score(y, labels)
    pts, how, axes = _to_2d(X, names)
    pic = _write(
        args.output,
        _scatter(pts, labels, f"{args.method}: {ids.size} clusters ({how})", axes=axes),
    )
    report["picture"] = str(pic)
    if args.labels_out:
        with open(args.labels_out, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["cluster"])
            w.writerows([[int(v)] for v in labels])
        report["labels_out"] = args.labels_out
    if args.json:
        print(json.dumps(report))
        return 0
    shape = f"{len(X)} rows x {len(names)} features"
    print(f"{args.method}: {shape} -> {ids.size} clusters in {ms:.1f} ms")
    for i, s in report["sizes"].items():
        print(f"  cluster {i:>3}: {s} rows")
    if report["noise"]:
        print(f"  noise      : {report['noise']} rows")
    for key in ("inertia", "bandwidth", "adjusted_rand_index"):
        if key in report:
            print(f"  {key.replace('_', ' ')}: {report[key]:.4g}")
    print(f"-> {pic}")
    return 0


def _scatter(
    pts: np.ndarray,
    labels: np.ndarray,
    title: str,
    names: Sequence[str] | np.ndarray | None = None,
    axes: tuple[str, str] = ("PC1", "PC2"),
) -> np.ndarray:
    from robopercept.viz import scatter_picture

    return scatter_picture(pts, labels, title=title, names=names, xlabel=axes[0], ylabel=axes[1])


# -- learn classify -------------------------------------------------------------------
def _model(args: argparse.Namespace) -> Any:
    from robopercept.learning import LDA, SVC, DecisionTreeClassifier, RandomForestClassifier

    if args.model == "tree":
        return DecisionTreeClassifier(max_depth=args.max_depth, random_state=args.seed)
    if args.model == "forest":
        return RandomForestClassifier(
            n_estimators=args.trees, max_depth=args.max_depth, n_jobs=-1, random_state=args.seed
        )
    if args.model == "svm":
        return SVC(C=args.C, kernel=args.kernel)
    return LDA()


@flag_errors(
    n_estimators="--trees",
    max_depth="--max-depth",
    C="-C",
    kernel="--kernel",
    test_size="--test-size",
)
def run_classify(args: argparse.Namespace) -> int:
    """Run ``robopercept classify`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.learning import (
        SavedModel,
        confusion_table,
        cross_val_score,
        evaluate_classifier,
        label_codes,
        read_table,
        save_model,
        standard_scaling,
        train_test_split,
    )
    from robopercept.viz import confusion_picture, curves_picture

    X, y, names = read_table(args.train, args.label)
    assert y is not None
    if args.test:
        Xt, yt, names_t = read_table(args.test, args.label)
        assert yt is not None
        if names_t != names:
            raise InputError(f"{args.test}: columns differ from {args.train}'s")
        Xtr, ytr = X, y
    else:
        if not 0.0 < args.test_size < 1.0:
            raise UsageError(f"--test-size must be in (0, 1); got {args.test_size}")
        Xtr, Xt, ytr, yt = train_test_split(
            X, y, test_size=args.test_size, stratify=y, random_state=args.seed
        )
    if args.cv and args.cv < 2:
        raise UsageError(f"--cv must be >= 2; got {args.cv}")
    codes, classes = label_codes(np.r_[ytr, yt])
    ctr, cte = codes[: len(ytr)], codes[len(ytr) :]
    mean = scale = None
    if args.standardize:
        mean, scale = standard_scaling(Xtr)
        Xtr, Xt = (Xtr - mean) / scale, (Xt - mean) / scale
    model = _model(args)
    t0 = time.perf_counter()
    model.fit(Xtr, ctr)
    fit_ms = (time.perf_counter() - t0) * 1e3
    ev = evaluate_classifier(model, Xt, cte, classes)
    rep = ev.report
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    label_names = [str(v) for v in rep.labels]
    confusion = confusion_picture(rep.confusion, label_names)
    written = {"confusion": str(_write(out / "confusion.png", confusion))}
    if ev.curves:
        ovr = " (one vs rest)" if len(ev.curves) > 1 else ""
        roc = [(c.fpr, c.tpr, f"{n} AUC {c.roc_auc:.3f}") for n, c in ev.curves.items()]
        pr = [
            (c.recall, c.precision, f"{n} AP {c.average_precision:.3f}")
            for n, c in ev.curves.items()
        ]
        pics = (
            ("roc", roc, "ROC", "false positive rate", "true positive rate"),
            ("pr", pr, "precision-recall", "recall", "precision"),
        )
        for key, curves, what, xlabel, ylabel in pics:
            pic = curves_picture(
                curves, title=f"{args.model}: {what}{ovr}", xlabel=xlabel, ylabel=ylabel
            )
            written[key] = str(_write(out / f"{key}.png", pic))
    report: dict[str, Any] = {
        "train": args.train,
        "test": args.test or f"stratified {args.test_size:.0%} of train (seed {args.seed})",
        "model": args.model,
        "train_rows": len(Xtr),
        "test_rows": len(Xt),
        "fit_ms": round(fit_ms, 1),
        **ev.to_dict(),
        "pictures": written,
    }
    if args.cv:
        cv = cross_val_score(_model(args), Xtr, ctr, cv=args.cv)
        report["cv_accuracy"] = {"mean": float(cv.mean()), "std": float(cv.std())}
    report["model_file"] = None
    if args.save:
        saved = SavedModel(
            model,
            feature_names=tuple(names),
            class_names=tuple(str(v) for v in classes[model.classes_]),
            label_column=args.label,
            mean=mean,
            scale=scale,
            info={"train": args.train, "model": args.model, "test_accuracy": rep.accuracy},
        )
        report["model_file"] = str(save_model(saved, args.save))
    (out / "report.json").write_text(json.dumps(report, indent=2))
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"{args.model}: trained on {len(Xtr)} rows in {fit_ms:.0f} ms, tested on {len(Xt)}")
    print(rep.table())
    print("confusion matrix (rows: true, columns: predicted)")
    print(confusion_table(rep.confusion, label_names))
    for n, v in report["curves"].items():
        print(f"  {n}: ROC AUC {v['roc_auc']:.4f}, average precision {v['average_precision']:.4f}")
    if "cv_accuracy" in report:
        cvr = report["cv_accuracy"]
        print(f"  {args.cv}-fold CV accuracy on train: {cvr['mean']:.4f} +- {cvr['std']:.4f}")
    files = [Path(v).name for v in written.values()] + ["report.json"]
    print(f"-> {out}/ ({', '.join(files)})")
    if report["model_file"]:
        print(f"-> {report['model_file']} (robopercept learn predict MODEL DATA.csv)")
    return 0


# -- learn predict --------------------------------------------------------------------
def run_predict(args: argparse.Namespace) -> int:
    """Run ``robopercept learn predict`` with the parsed ``args``; returns the exit status."""
    from robopercept.learning import load_model, predict_table

    saved = load_model(args.model)
    t0 = time.perf_counter()
    result = predict_table(saved, args.data, label=args.label)
    ms = (time.perf_counter() - t0) * 1e3
    written = result.write_csv(args.output)
    labels = saved.labels
    report: dict[str, Any] = {
        "model": args.model,
        "kind": type(saved.model).__name__,
        "data": args.data,
        "features": list(saved.feature_names) if saved.feature_names else None,
        "classes": None if labels is None else [str(v) for v in labels.tolist()],
        **result.to_dict(),
        "output": str(written),
        "ms": round(ms, 1),
    }
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"predict: {report['rows']} rows of {args.data} with {report['kind']} ({args.model})")
    for name, n in report["counts"].items():
        print(f"  {name}: {n} rows")
    if result.accuracy is not None:
        print(
            f"  accuracy against column {result.label!r}: {result.accuracy:.4f} "
            f"({result.correct}/{report['rows']})"
        )
        if result.unknown:
            print(f"  {result.unknown} rows have a class the model never saw")
    print(f"-> {written}")
    return 0


# -- learn reduce ---------------------------------------------------------------------
def run_reduce(args: argparse.Namespace) -> int:
    """Run ``robopercept reduce`` with the parsed ``args``; returns the exit status."""
    from robopercept.learning import LDA, PCA, label_codes, read_table

    if args.method == "lda" and args.label is None:
        raise UsageError("LDA needs the classes: name their column with --label")
    X, y, names = read_table(args.data, args.label)
    codes = classes = None
    if y is not None:
        codes, classes = label_codes(y)
    if args.method == "lda":
        if codes is None:
            raise UsageError("LDA needs the classes: name their column with --label")
        if classes is not None and classes.size < 3:
            raise InputError(
                f"LDA gives at most c - 1 = {classes.size - 1} axis for {classes.size} "
                "classes; a 2-D picture needs 3 or more (use --method pca)"
            )
        model: Any = LDA(n_components=2).fit(X, codes)
    else:
        if X.shape[1] < 2:
            raise InputError("PCA to 2-D needs at least two feature columns")
        model = PCA(2, standardize=args.standardize).fit(X)
    Z = model.transform(X)[:, :2]
    ratio = [float(v) for v in model.explained_variance_ratio_[:2]]
    what = "variance" if args.method == "pca" else "between-class variance"
    title = f"{args.method.upper()}: axis 1 {ratio[0]:.1%}, axis 2 {ratio[1]:.1%} of the {what}"
    a = "PC" if args.method == "pca" else "LD"
    axes = (f"{a}1 ({ratio[0]:.1%})", f"{a}2 ({ratio[1]:.1%})")
    pic = _write(args.output, _scatter(Z, codes, title, classes, axes=axes))
    report = {
        "data": args.data,
        "rows": len(X),
        "features": names,
        "method": args.method,
        "explained_variance_ratio": ratio,
        "picture": str(pic),
    }
    if args.transformed:
        with open(args.transformed, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["axis1", "axis2"] + (["label"] if y is not None else []))
            for k, z in enumerate(Z):
                w.writerow([f"{z[0]:.9g}", f"{z[1]:.9g}"] + ([y[k]] if y is not None else []))
        report["transformed"] = args.transformed
    if args.json:
        print(json.dumps(report))
    else:
        print(f"{args.method}: {len(X)} rows x {len(names)} features -> 2-D; {title}")
        print(f"-> {pic}")
    return 0
