"""Tests of Mask R-CNN (robopercept.nn.detection.mask_rcnn.MaskRCNN) and of pasting per-box masks
back into the image (robopercept.nn.ops.roi.paste_masks): hand cases, the round trip with
RoI Align, the mask loss by its formula, shapes in train and eval mode, overfitting two
canvases to a high mask AP, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.mask_rcnn import MaskRCNN  # noqa: E402
from robopercept.nn.detection.synthetic import digits_detection_set  # noqa: E402
from robopercept.nn.detection.train import evaluate_detector, train_detector  # noqa: E402
from robopercept.nn.detection.zoo import build_detector, detect_arrays, load_detector, save_detector  # noqa: E402
from robopercept.nn.ops.roi import paste_masks, roi_align  # noqa: E402
from robopercept.nn.train.config import TrainConfig  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def build(num_classes: int = 10, **kw):
    torch.manual_seed(0)
    kw = {
        "width": 8,
        "hidden": 64,
        "box_batch_size": 64,
        "rpn_batch_size": 64,
        "mask_channels": 16,
        "mask_convs": 2,
        **kw,
    }
    return MaskRCNN(num_classes, **kw)


def disk(h: int, w: int, cx: float, cy: float, r: float) -> torch.Tensor:
    yy, xx = torch.meshgrid(
        torch.arange(h, dtype=torch.float64) + 0.5,
        torch.arange(w, dtype=torch.float64) + 0.5,
        indexing="ij",
    )
    return ((xx - cx) ** 2 + (yy - cy) ** 2 < r * r).to(torch.uint8)


def tight_box(mask: torch.Tensor) -> torch.Tensor:
    rc = torch.nonzero(mask)
    return torch.tensor(
        [[rc[:, 1].min(), rc[:, 0].min(), rc[:, 1].max() + 1, rc[:, 0].max() + 1]],
        dtype=torch.float32,
    )


def tiny_batch():
    masks0 = torch.stack([disk(64, 64, 24, 30, 14), disk(64, 64, 52, 52, 8)])
    masks1 = disk(48, 56, 35, 17, 12)[None]
    g = torch.Generator().manual_seed(1)
    images = [torch.rand(3, 64, 64, generator=g), torch.rand(3, 48, 56, generator=g)]
    targets = [
        {
            "boxes": torch.cat([tight_box(m) for m in masks0]),
            "labels": torch.tensor([3, 1]),
            "masks": masks0,
        },
        {"boxes": tight_box(masks1[0]), "labels": torch.tensor([7]), "masks": masks1},
    ]
    return images, targets


# --------------------------------------------------------------------------- paste_masks
class TestPasteMasks:
    def test_a_mask_of_ones_covers_the_pixels_whose_centres_the_box_holds(self):
        g = np.random.default_rng(0)
        for _ in range(50):
            x1, y1 = g.uniform(-5, 30, 2)
            x2, y2 = x1 + g.uniform(0.2, 25), y1 + g.uniform(0.2, 25)
            box = torch.tensor([[x1, y1, x2, y2]], dtype=torch.float32)
            out = paste_masks(torch.ones(1, 7, 7), box, (32, 40))[0]
            c = np.arange(40) + 0.5
            r = np.arange(32) + 0.5
            b = box[0].double().numpy()
            expect = ((r[:, None] >= b[1]) & (r[:, None] <= b[3])) & (
                (c[None] >= b[0]) & (c[None] <= b[2])
            )
            np.testing.assert_array_equal(out.numpy() > 0.5, expect)

    def test_bilinear_values_hand_case(self):
        # a 2 x 2 mask [[0, 1], [0, 1]] over the box (0, 0, 4, 4): column c samples
        # u = (c + 1/2) * 2 / 4 - 1/2 = -0.25, 0.25, 0.75, 1.25 -> clamped 0, 0.25, 0.75, 1
        m = torch.tensor([[[0.0, 1.0], [0.0, 1.0]]])
        out = paste_masks(m, torch.tensor([[0.0, 0.0, 4.0, 4.0]]), (4, 5))[0]
        row = [0.0, 0.25, 0.75, 1.0, 0.0]
        torch.testing.assert_close(out, torch.tensor([row] * 4))

    def test_round_trip_with_roi_align(self):
        # a disk RoI-aligned (aligned=True) onto 28 x 28 cells over its tight box and
        # pasted back thresholded at 0.5 gives the disk again (measured: IoU 1.0; a
        # half-pixel shift between the two conventions gives about 0.93)
        for cx, cy, r in ((30.3, 25.7, 15.0), (12.0, 40.2, 6.5), (47.9, 31.1, 11.0)):
            d = disk(64, 64, cx, cy, r).float()
            box = tight_box(d)
            rows = torch.cat([torch.zeros(1, 1), box], 1)
            cells = roi_align(d[None, None], rows, 28, 1.0, sampling_ratio=2, aligned=True)
            back = paste_masks(cells[:, 0], box, (64, 64))[0] > 0.5
            iou = float((back & (d > 0)).sum() / (back | (d > 0)).sum())
            assert iou >= 0.98, iou

    def test_shapes_empty_and_one_channel_layout(self):
        assert paste_masks(torch.zeros(0, 28, 28), torch.zeros(0, 4), (5, 6)).shape == (0, 5, 6)
        m = torch.rand(3, 1, 14, 14, generator=torch.Generator().manual_seed(0))
        b = torch.tensor([[0.0, 0, 10, 10], [5, 5, 9, 20], [30, 30, 40, 40]])
        a = paste_masks(m, b, (16, 16))
        torch.testing.assert_close(a, paste_masks(m[:, 0], b, (16, 16)))
        assert a.shape == (3, 16, 16) and float(a[2].abs().sum()) == 0.0  # outside the image

    @pytest.mark.parametrize(
        ("call", "msg"),
        [
            (lambda: paste_masks(torch.ones(2, 4, 4), torch.zeros(1, 4), (4, 4)), "pair up"),
            (lambda: paste_masks(torch.ones(1, 4), torch.zeros(1, 4), (4, 4)), r"\(D, M, M\)"),
            (
                lambda: paste_masks(
                    torch.ones(1, 4, 4, dtype=torch.int64), torch.zeros(1, 4), (4, 4)
                ),
                "float",
            ),
            (lambda: paste_masks(torch.ones(1, 4, 4), torch.zeros(1, 4), (0, 4)), "positive ints"),
            (
                lambda: paste_masks(torch.ones(1, 4, 4), torch.tensor([[3.0, 0, 1, 1]]), (4, 4)),
                "x1 <= x2",
            ),
        ],
    )
    def test_bad_input(self, call, msg):
        with pytest.raises(InputError, match=msg):
            call()


# --------------------------------------------------------------------------- MaskRCNN
def test_train_losses_finite_positive_and_gradients_flow():
    m = build().train()
    images, targets = tiny_batch()
    losses = m(images, targets)
    assert set(losses) == {
        "loss_rpn_objectness",
        "loss_rpn_box",
        "loss_classifier",
        "loss_box",
        "loss_mask",
    }
    for name, v in losses.items():
        assert v.ndim == 0 and bool(torch.isfinite(v)) and float(v.detach()) > 0, name
    sum(losses.values()).backward()
    for name, p in m.named_parameters():
        assert p.grad is not None and bool(p.grad.abs().sum() > 0), name


def test_mask_targets_are_the_instance_mask_roi_aligned_over_the_region():
    m = build()
    d = disk(40, 40, 20, 18, 9)
    masks = torch.stack([torch.zeros_like(d), d])
    rois = torch.tensor([[8.0, 6.0, 32.0, 30.0], [0.0, 0.0, 20.0, 20.0]])
    t = m.roi_heads.mask_head.mask_targets(rois, masks, torch.tensor([1, 1]))
    assert t.shape == (2, 28, 28) and float(t.min()) >= 0 and float(t.max()) <= 1
    ref = roi_align(d.float()[None, None], [rois], 28, 1.0, sampling_ratio=2, aligned=True)
    torch.testing.assert_close(t, ref[:, 0])
    # matched to the empty mask: all zero
    assert (
        float(m.roi_heads.mask_head.mask_targets(rois[:1], masks, torch.tensor([0])).sum()) == 0.0
    )


def test_mask_loss_is_the_bce_of_the_ground_truth_class_map():
    # rebuild the loss from its parts: the sampled foreground regions (the same seed
    # draws the same sample), their class maps and their RoI-aligned targets
    m = build().train()
    images, targets = tiny_batch()
    torch.manual_seed(3)
    loss = m(images, targets)["loss_mask"]
    torch.manual_seed(3)
    batch, sizes, tgts = m._prepare(images, targets)
    feats = m.backbone(batch)[-1]
    obj, reg, anchors = m.rpn.anchor_outputs(feats, (int(batch.shape[2]), int(batch.shape[3])))
    props, _ = m.rpn.filter_proposals(obj, reg, anchors, sizes)
    m.rpn.losses(obj, reg, anchors, tgts)  # draws its samples, as forward does
    rois, labels, _, matched = m.roi_heads.sample_regions(props, tgts)
    fg = [lab > 0 for lab in labels]
    logits = m.roi_heads.mask_head.mask_logits(feats, [r[f] for r, f in zip(rois, fg, strict=True)])
    cls = torch.cat([lab[f] for lab, f in zip(labels, fg, strict=True)])
    zz = logits[torch.arange(cls.numel()), cls - 1]
    yy = torch.cat(
        [
            m.roi_heads.mask_head.mask_targets(r[f], t["masks"], mt[f])
            for r, f, mt, t in zip(rois, fg, matched, tgts, strict=True)
        ]
    )
    assert cls.numel() >= 3  # every object is among the sampled foreground
    p = torch.sigmoid(zz.double())
    hand = -(yy * torch.log(p) + (1 - yy) * torch.log(1 - p)).mean()
    torch.testing.assert_close(loss.double(), hand, rtol=1e-5, atol=1e-6)


def test_eval_outputs_masks_inside_their_boxes():
    m = build(score_thresh=0.0).eval()
    images, _ = tiny_batch()
    out = m.predict(images)
    for o, im in zip(out, images, strict=True):
        assert set(o) == {"boxes", "labels", "scores", "masks"}
        d = o["boxes"].shape[0]
        h, w = im.shape[1:]
        assert d >= 1 and o["masks"].shape == (d, 1, h, w)
        assert float(o["masks"].min()) >= 0 and float(o["masks"].max()) <= 1
        # nothing outside the box: pixel centres beyond it are 0
        for box, mask in zip(o["boxes"], o["masks"][:, 0], strict=True):
            x2 = int(np.floor(float(box[2]) - 0.5)) + 1
            assert float(mask[:, x2:].abs().sum()) == 0.0


def test_an_image_without_objects_trains_and_an_empty_eval_has_the_shapes():
    m = build().train()
    losses = m(
        [torch.rand(3, 32, 32)],
        [
            {
                "boxes": torch.zeros(0, 4),
                "labels": torch.zeros(0, dtype=torch.int64),
                "masks": torch.zeros(0, 32, 32, dtype=torch.uint8),
            }
        ],
    )
    assert float(losses["loss_mask"].detach()) == 0.0
    sum(losses.values()).backward()
    e = build(score_thresh=1.0).eval().predict([torch.rand(3, 24, 40)])[0]
    assert e["boxes"].shape == (0, 4) and e["masks"].shape == (0, 1, 24, 40)


@pytest.mark.parametrize(
    ("masks", "msg"),
    [
        (None, "no 'masks'"),
        (torch.zeros(1, 16, 17, dtype=torch.uint8), r"must be \(1, 16, 16\)"),
        (torch.zeros(2, 16, 16, dtype=torch.uint8), r"must be \(1, 16, 16\)"),
        (torch.full((1, 16, 16), float("nan")), "NaN"),
    ],
)
def test_bad_mask_targets(masks, msg):
    t = {"boxes": torch.tensor([[1.0, 2, 8, 9]]), "labels": torch.tensor([1])}
    if masks is not None:
        t["masks"] = masks
    with pytest.raises(InputError, match=msg):
        build().train()([torch.rand(3, 16, 16)], [t])


def test_constructor_and_evaluation_refusals():
    with pytest.raises(InputError, match="mask_pool_size"):
        MaskRCNN(2, width=4, mask_pool_size=0)
    with pytest.raises(InputError, match="mask_convs"):
        MaskRCNN(2, width=4, mask_convs=-1)
    ds = digits_detection_set(1, (32, 32), (1, 1), rng=0, scale=(12, 16))
    with pytest.raises(InputError, match="gives none"):
        evaluate_detector(build_detector("faster", 10, width=4), ds, iou_type="segm")
    with pytest.raises(InputError, match="iou_type"):
        evaluate_detector(build(), ds, iou_type="keypoints")


def test_checkpoint_round_trip_and_numpy_detections(tmp_path):
    m = build(2, score_thresh=0.0)
    settings = {"width": 8, "hidden": 64, "mask_channels": 16, "mask_convs": 2, "score_thresh": 0.0}
    save_detector(tmp_path / "m.pt", m, "maskrcnn", settings, ["a", "b"])
    m2, info = load_detector(tmp_path / "m.pt")
    assert type(m2).__name__ == "MaskRCNN" and info["kind"] == "maskrcnn"
    im = np.random.default_rng(0).integers(0, 255, (40, 48, 3), np.uint8)
    a = detect_arrays(m.eval(), [im])[0]
    b = detect_arrays(m2, [im])[0]
    assert a["masks"].shape == (a["boxes"].shape[0], 40, 48) and a["masks"].dtype == bool
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


def test_overfits_two_canvases_to_a_high_mask_ap():
    # two 64 x 64 canvases of one real digit each with their stroke masks: the mask
    # branch (targets, loss and pasting that agree) fits them to mask AP50 >= 0.9 in 60
    # steps; with the targets taken 4 px off their regions it scored mask AP50 0.0
    # (measured), as thin strokes then miss their own pixels
    ds = digits_detection_set(2, (64, 64), (1, 1), rng=0, scale=(16, 32))
    m = build()
    cfg = TrainConfig(
        epochs=60, batch_size=2, lr=1e-3, device="cpu", schedule="constant", weight_decay=0.0
    )
    hist = train_detector(m, ds, cfg, progress=False)
    assert hist.losses[-1]["loss_mask"] < 0.5 * hist.losses[0]["loss_mask"]
    segm = evaluate_detector(m, ds, iou_type="segm")
    assert segm.stats[1] >= 0.9, segm.stats
