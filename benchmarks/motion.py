"""Motion: Lucas-Kanade against cv2.calcOpticalFlowPyrLK on Middlebury RubberWhale, and
the Gaussian background model's frame rate at 640 x 480 (cv2 MOG2 beside it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks._harness import Record, paired_ms

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _flo(path: Path) -> np.ndarray:
    with path.open("rb") as fh:
        fh.read(4)
        w, h = np.frombuffer(fh.read(8), np.int32)
        return np.frombuffer(fh.read(), np.float32).reshape(h, w, 2)


def run(repeats: int) -> tuple[list[Record], dict]:
    import cv2

    from robopercept.imaging import read_image
    from robopercept.motion import GaussianBackground, lucas_kanade, moving_blobs

    records = []
    folder = DATA / "flow" / "middlebury_rubberwhale"
    a = read_image(folder / "RubberWhale1.png", mode="gray")
    b = read_image(folder / "RubberWhale2.png", mode="gray")
    gt = _flo(folder / "RubberWhale.flo")
    pts = cv2.goodFeaturesToTrack(a, 1000, 0.01, 5)[:, 0]
    p64 = pts.astype(np.float64)

    def ours():
        return lucas_kanade(a, b, p64, window=21, levels=3)

    def ref():
        return cv2.calcOpticalFlowPyrLK(a, b, pts[:, None], None, winSize=(21, 21), maxLevel=3)

    xi, yi = np.round(p64).astype(int).T
    known = (np.abs(gt[yi, xi]) < 1e9).all(axis=1)

    def epe(end, ok):
        e = np.linalg.norm(end - p64 - gt[yi, xi], axis=1)[known & ok]
        return float(np.median(e)), float(e.mean())

    o, (r, st, _) = ours(), ref()
    o_med, o_mean = epe(o.end, o.status)
    r_med, r_mean = epe(r[:, 0].astype(np.float64), st[:, 0] == 1)
    ours_ms, ref_ms = paired_ms(ours, ref, repeats=repeats, warmup=3)
    records.append(
        Record("lucas_kanade", f"{len(pts)} Shi-Tomasi points, 21x21, 3 levels, 584x388",
               ours_ms, ref_ms, "cv2.calcOpticalFlowPyrLK", "median endpoint error px",
               o_med, 2.0, {"reference_median_epe": r_med, "mean_epe": o_mean,
                            "reference_mean_epe": r_mean,
                            "tracked": int(o.status.sum()), "reference_tracked": int(st.sum())})
    )  # fmt: skip

    frames, masks = moving_blobs(60, (640, 480), n_blobs=6, rng=0)
    rgb = np.repeat(frames[..., None], 3, axis=3)

    def run_ours(model, seq):
        def go():
            for f in seq[20:]:
                model.apply(f)

        return go

    for name, seq in (("gray", frames), ("rgb", rgb)):
        model = GaussianBackground(init_frames=20)
        for f in seq[:20]:
            model.apply(f)
        mog = cv2.createBackgroundSubtractorMOG2()
        for f in seq[:20]:
            mog.apply(f)

        def ref_go(mog=mog, seq=seq):
            for f in seq[20:]:
                mog.apply(f)

        o_ms, r_ms = paired_ms(run_ours(model, seq), ref_go, repeats=max(3, repeats // 3), warmup=1)
        n = len(seq) - 20
        tp = fp = fn = 0
        check = GaussianBackground(init_frames=20)
        for t, f in enumerate(seq):
            m = check.apply(f)
            if t >= 20:
                tp += int(np.sum(m & masks[t]))
                fp += int(np.sum(m & ~masks[t]))
                fn += int(np.sum(~m & masks[t]))
        records.append(
            Record("gaussian_background", f"640x480 {name}, 3x3 majority clean-up, per frame",
                   o_ms / n, r_ms / n, "cv2 MOG2 (a different model, for scale)",
                   "foreground F1 on moving blobs", 2 * tp / (2 * tp + fp + fn), None,
                   {"fps": 1000.0 * n / o_ms, "target_fps": 200})
        )  # fmt: skip
    from robopercept.tracking import MultiObjectTracker

    gen = np.random.default_rng(0)
    pos, vel = gen.uniform(0, 1000, (50, 2)), gen.normal(0, 2, (50, 2))
    dets = []
    for _ in range(60):
        pos = pos + vel
        dets.append(np.c_[pos + gen.normal(0, 1, (50, 2)), np.full((50, 2), 30.0)])
    trk = MultiObjectTracker(min_hits=1)
    for d in dets[:10]:
        trk.update(d)

    def mot():
        for d in dets[10:]:
            trk.update(d)

    ms = paired_ms(mot, lambda: None, repeats=1, warmup=0)[0] / 50
    records.append(
        Record("multi_object_update", "50 tracks, 50 detections, IoU cost", ms, float("nan"),
               "none", "tracks alive", float(len(trk.tracks)), None, {"target_ms": 1.0})
    )  # fmt: skip
    return records, {"data": "Middlebury RubberWhale; synthetic moving blobs 640x480"}
