"""Make ``docs/img/hog_face_pr.png``: the precision/recall curve on which the bundled
HOG face model's default threshold was chosen (issue 30).

Run from the repository root (about 2 minutes of CPU: it retrains the bundled model,
exactly, with :func:`robopercept.learning.hog_detector.train_face_detector`)::

    PYTHONPATH=src python docs/make_hog_pr_picture.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robopercept.imaging import write_image
from robopercept.learning.hog_detector import ThresholdChoice, train_face_detector
from robopercept.viz.figure import agg_figure, figure_to_rgb, readable_dpi

OUT = Path(__file__).parent / "img" / "hog_face_pr.png"


def pr_picture(choice: ThresholdChoice, width: int = 1200, height: int = 700) -> np.ndarray:
    """The curve, its F1-best point and the precision-0.95 point, as an RGB picture."""
    fig = agg_figure(width, height, layout="constrained", dpi=readable_dpi(width, height))
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(choice.curve_recall, choice.curve_precision, color="tab:blue", lw=2, label="PR curve")
    ax.plot(choice.recall, choice.precision, "o", ms=10, color="tab:red",
            label=f"chosen ({choice.rule}): t = {choice.threshold:.2f}")  # fmt: skip
    ax.set(xlabel="recall (held-out faces found)", ylabel="precision",
           xlim=(0, 1.02), ylim=(0, 1.02),
           title=f"{choice.n_positive} held-out faces, {choice.n_negative} non-faces")  # fmt: skip
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left")
    bx = fig.add_subplot(1, 2, 2)
    t = choice.curve_thresholds
    p, r = choice.curve_precision[:-1], choice.curve_recall[:-1]
    f1 = np.where(p + r > 0, 2 * p * r / np.maximum(p + r, 1e-12), 0)
    bx.plot(t, p, label="precision", lw=2)
    bx.plot(t, r, label="recall", lw=2)
    bx.plot(t, f1, label="F1", lw=2, color="tab:green")
    bx.axvline(choice.threshold, color="tab:red", ls="--", label="default threshold")
    bx.axvline(0.0, color="gray", ls=":", label="old default (0)")
    bx.set(xlabel="SVM score threshold", ylabel="share", ylim=(0, 1.02),
           title="by threshold")  # fmt: skip
    bx.grid(alpha=0.3)
    bx.legend(loc="best")
    return figure_to_rgb(fig)


def main() -> None:
    _, report = train_face_detector(random_state=0)
    write_image(OUT, pr_picture(report["choice"]))
    print(f"threshold {report['threshold']:.4f} -> {OUT}")


if __name__ == "__main__":
    main()
