"""Tests of robopercept.nn.detection.augment: FlipRotate and ScaleJitter move boxes and
masks with the pixels, seeded."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.augment import FlipRotate, ScaleJitter  # noqa: E402


# --------------------------------------------------------------------------- FlipRotate
def _tight(mask: torch.Tensor) -> list[float]:
    ys, xs = torch.nonzero(mask, as_tuple=True)
    return [float(xs.min()), float(ys.min()), float(xs.max() + 1), float(ys.max() + 1)]


@pytest.mark.parametrize(
    ("kw", "seed"),
    [({"horizontal": 1.0}, 0), ({"horizontal": 0.0, "vertical": 1.0}, 0)]
    + [({"horizontal": 0.5, "vertical": 0.5, "rotate90": True}, s) for s in range(12)],
)
def test_flip_rotate_moves_boxes_and_masks_with_the_pixels(kw, seed):
    # a non-square image with two lit rectangles: after any transform, each box must be
    # the tight box of its lit pixels, and the mask must be those pixels
    h, w = 12, 20
    image = torch.zeros(3, h, w)
    rects = [(2, 1, 7, 4), (11, 5, 19, 12)]  # xyxy, pixel edges
    masks = torch.zeros(2, h, w, dtype=torch.uint8)
    for k, (x1, y1, x2, y2) in enumerate(rects):
        image[k, y1:y2, x1:x2] = 1.0
        masks[k, y1:y2, x1:x2] = 1
    target = {"boxes": torch.tensor(rects, dtype=torch.float32), "masks": masks, "labels": 7}
    out_im, out_t = FlipRotate(**kw, generator=seed)(image, target)
    assert out_t["labels"] == 7 and sorted(out_im.shape[1:]) == [h, w]
    for k in range(2):
        assert out_t["boxes"][k].tolist() == _tight(out_im[k] > 0)
        assert torch.equal(out_t["masks"][k].bool(), out_im[k] > 0)
    assert torch.equal(target["boxes"], torch.tensor(rects, dtype=torch.float32))  # not in place


def test_flip_rotate_is_seeded_and_draws_every_turn():
    image = torch.arange(12.0).reshape(1, 3, 4)
    t = {"boxes": torch.zeros(0, 4)}
    runs = []
    for _ in range(2):
        f = FlipRotate(0.5, 0.5, True, generator=3)
        runs.append([f(image, t)[0] for _ in range(40)])
    assert all(torch.equal(x, y) for x, y in zip(*runs, strict=True))
    # 8 distinct outcomes of the dihedral group on an asymmetric image
    assert len({tuple(x.flatten().tolist()) + tuple(x.shape) for x in runs[0]}) == 8


# --------------------------------------------------------------------------- ScaleJitter
def test_scale_jitter_hand_case_zoom_in_and_out():
    # scale exactly 2 on a 10x10 image: the box (4,4)-(6,6) becomes 4 px wide at
    # 2 * 4 - o; scale exactly 0.5 on 20x20: the box halves and moves by the pad offset
    box = {"boxes": torch.tensor([[4.0, 4, 6, 6]])}
    kept = []
    for seed in range(5):
        # min_visible 1: the box is kept only whole, then exactly 4 x 4
        im, t = ScaleJitter((2.0, 2.0), 1.0, generator=seed)(torch.zeros(3, 10, 10), box)
        assert im.shape == (3, 10, 10)
        for x1, y1, x2, y2 in t["boxes"].tolist():
            assert (x2 - x1, y2 - y1) == (4.0, 4.0)
            assert 0 <= 8 - x1 <= 10 and 0 <= 8 - y1 <= 10  # offsets within 0..sW - W
            kept.append(seed)
        big = {"boxes": torch.tensor([[4.0, 8, 12, 16]])}
        im, t = ScaleJitter((0.5, 0.5), fill=0.25, generator=seed)(torch.ones(1, 20, 20), big)
        x1, y1, x2, y2 = t["boxes"][0].tolist()
        assert (x2 - x1, y2 - y1) == (4.0, 4.0)
        ox, oy = x1 - 2.0, y1 - 4.0  # the pad offset: where the 10x10 image went
        assert im[0, int(oy) : int(oy) + 10, int(ox) : int(ox) + 10].eq(1).all()
        assert im.sum() == 100 + 0.25 * 300
    assert kept  # some offsets keep the whole box


@pytest.mark.parametrize("seed", range(10))
def test_scale_jitter_moves_boxes_and_masks_with_the_pixels(seed):
    # two lit rectangles; after the zoom each kept box must be the tight box of its
    # lit pixels within the bilinear resampling's one pixel, and its mask those pixels
    h, w = 40, 56
    image = torch.zeros(2, h, w)
    rects = [(6, 4, 22, 16), (30, 20, 50, 36)]
    masks = torch.zeros(2, h, w, dtype=torch.uint8)
    for k, (x1, y1, x2, y2) in enumerate(rects):
        image[k, y1:y2, x1:x2] = 1.0
        masks[k, y1:y2, x1:x2] = 1
    target = {
        "boxes": torch.tensor(rects, dtype=torch.float32),
        "labels": torch.tensor([3, 5]),
        "masks": masks,
        "image_id": 9,
    }
    out_im, out_t = ScaleJitter((0.6, 1.6), min_visible=0.0, generator=seed)(image, target)
    assert out_im.shape == image.shape and out_t["image_id"] == 9
    kept = out_t["labels"].tolist()
    assert len(out_t["boxes"]) == len(kept) == len(out_t["masks"])
    for j, label in enumerate(kept):
        k = [3, 5].index(label)
        lit = out_im[k] > 0.5
        got = out_t["boxes"][j]
        assert torch.allclose(got, torch.tensor(_tight(lit)), atol=1.0), (got, _tight(lit))
        # nearest-neighbour mask and bilinear image agree but on the edge pixels
        assert (out_t["masks"][j].bool() ^ lit).sum() <= 2 * (h + w)
    assert torch.equal(target["boxes"], torch.tensor(rects, dtype=torch.float32))


def test_scale_jitter_drops_boxes_that_leave_the_image_with_their_fields():
    # at 3x only a 1/9 of the image stays: a corner box in the far corner is cut off
    # whatever the offset, the per-box fields follow, and min_visible decides the rest
    image = torch.zeros(3, 30, 30)
    target = {"boxes": torch.tensor([[0.0, 0, 4, 4], [26.0, 26, 30, 30]]),
              "labels": torch.tensor([1, 2])}  # fmt: skip
    counts = set()
    for seed in range(20):
        _, t = ScaleJitter((3.0, 3.0), min_visible=0.5, generator=seed)(image, target)
        assert len(t["boxes"]) == len(t["labels"]) <= 1
        counts.add(len(t["boxes"]))
    assert counts <= {0, 1}
    _, t = ScaleJitter((3.0, 3.0), min_visible=1.0, generator=0)(image, target)
    area = (t["boxes"][:, 2] - t["boxes"][:, 0]) * (t["boxes"][:, 3] - t["boxes"][:, 1])
    assert torch.all(area == 144.0)  # only whole boxes: 12 x 12


def test_scale_jitter_is_seeded_and_log_uniform():
    image = torch.rand(3, 16, 16, generator=torch.Generator().manual_seed(0))
    t = {"boxes": torch.zeros(0, 4)}
    a = [ScaleJitter((0.5, 2.0), generator=4)(image, t)[0] for _ in range(1)]
    b = [ScaleJitter((0.5, 2.0), generator=4)(image, t)[0] for _ in range(1)]
    assert torch.equal(a[0], b[0])
    j = ScaleJitter((0.25, 4.0), generator=1)
    zoomed_in = sum(
        j(torch.ones(1, 8, 8), t)[0].gt(0.999).all().item() for _ in range(400)
    )  # s >= 1 leaves no padding: P = 1/2 when log-uniform
    assert 160 < zoomed_in < 240


@pytest.mark.parametrize(
    ("kw", "args", "msg"),
    [
        ({"scale": (0.0, 1.0)}, None, "scale low"),
        ({"scale": (1.5, 1.0)}, None, "scale high"),
        ({"scale": 1.2}, None, "pair"),
        ({"min_visible": 2.0}, None, "min_visible"),
        ({}, (torch.zeros(8, 8), {"boxes": torch.zeros(0, 4)}), "(C, H, W)"),
        ({}, (torch.zeros(3, 8, 8, dtype=torch.uint8), {"boxes": torch.zeros(0, 4)}), "floating"),
        ({}, (torch.zeros(3, 8, 8), {"labels": 1}), "'boxes'"),
    ],
)
def test_scale_jitter_bad_input(kw, args, msg):
    with pytest.raises(InputError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        ScaleJitter(**kw)(*args)


@pytest.mark.parametrize(
    ("kw", "args", "msg"),
    [
        ({"horizontal": 1.5}, None, "horizontal"),
        ({"rotate90": "yes"}, None, "rotate90"),
        ({}, (torch.zeros(8, 8), {"boxes": torch.zeros(0, 4)}), "(C, H, W)"),
        ({}, (torch.zeros(3, 8, 8), {"labels": 1}), "'boxes'"),
    ],
)
def test_flip_rotate_bad_input(kw, args, msg):
    with pytest.raises(InputError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        f = FlipRotate(**kw)
        f(*args)
