"""Tests of robopercept.nn.detection.tta: every view maps back onto the original box, the
fusion by hand, and an untrained FCOS's shapes and refusals."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from tests.nn.detection.detectors import build  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


class _BrightBox(torch.nn.Module):
    """A stand-in detector: the bounding box of the pixels above 0.5 (label 1, score
    0.9): exact in every view, so TTA must give back the box of the original image."""

    def forward(self, images):
        out = []
        for im in images:
            ys, xs = torch.nonzero(im[0] > 0.5, as_tuple=True)
            box = [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]
            out.append(
                {
                    "boxes": torch.stack(box).float()[None],
                    "labels": torch.tensor([1]),
                    "scores": torch.tensor([0.9]),
                }
            )
        return out

    def predict(self, images):
        return self(images)


class _Scripted(torch.nn.Module):
    """Returns scripted detections per call (one call per view, one image)."""

    def __init__(self, per_view):
        super().__init__()
        self.per_view = iter(per_view)

    def forward(self, images):
        boxes, scores = next(self.per_view)
        n = len(scores)
        return [
            {
                "boxes": torch.tensor(boxes, dtype=torch.float32).reshape(n, 4),
                "labels": torch.ones(n, dtype=torch.int64),
                "scores": torch.tensor(scores),
            }
        ]


@pytest.mark.parametrize("views", ["hflip", "flips", "dihedral"])
def test_tta_maps_every_view_back_onto_the_original_box(views):
    from robopercept.nn.detection.tta import TTA_VIEWS, TestTimeAugmentation

    image = torch.zeros(3, 20, 31)
    image[:, 3:11, 5:24] = 1.0  # box (5, 3, 24, 11), not symmetric in the image
    tta = TestTimeAugmentation(_BrightBox(), views).eval()
    out = tta([image])[0]
    assert len(TTA_VIEWS[views]) == {"hflip": 2, "flips": 4, "dihedral": 8}[views]
    # exact up to float32 rounding of the score-weighted mean (sum of 0.9 b / sum of 0.9)
    torch.testing.assert_close(out["boxes"], torch.tensor([[5.0, 3.0, 24.0, 11.0]]))
    assert out["scores"].tolist() == pytest.approx([0.9])  # seen in every view


def test_tta_fusion_hand_case():
    from robopercept.nn.detection.tta import TestTimeAugmentation

    # 'hflip' on a 100-px-wide image: view 1's boxes are mirrored back (x -> 100 - x).
    # Cluster A: (10,10,20,20) s=0.8 in view 0, and view 1's (80,10,90,20) -> (10,10,20,20)
    #   shifted by 2 px: (78,10,88,20) -> (12,10,22,20), s=0.4.
    # Cluster B: (50,50,60,60) s=0.6 in view 0 only.
    per_view = [
        ([[10, 10, 20, 20], [50, 50, 60, 60]], [0.8, 0.6]),
        ([[78, 10, 88, 20]], [0.4]),
    ]
    tta = TestTimeAugmentation(_Scripted(per_view), "hflip", iou_thresh=0.5).eval()
    out = tta([torch.zeros(3, 100, 100)])[0]
    # A: box x1 (0.8 * 10 + 0.4 * 12) / 1.2 = 32 / 3, x2 (0.8 * 20 + 0.4 * 22) / 1.2
    #    = 62 / 3; score (0.8 + 0.4) / 2 = 0.6
    # B: score (0.6 + 0) / 2 = 0.3
    torch.testing.assert_close(
        out["boxes"], torch.tensor([[32 / 3, 10, 62 / 3, 20], [50.0, 50, 60, 60]])
    )
    torch.testing.assert_close(out["scores"], torch.tensor([0.6, 0.3]))
    assert out["labels"].tolist() == [1, 1]


def test_tta_with_an_untrained_fcos_shapes_and_refusals():
    from robopercept.nn.detection.tta import TestTimeAugmentation

    model = build("fcos").eval()
    model.score_thresh = 0.0  # every location: many detections per view
    tta = TestTimeAugmentation(model, "dihedral", detections_per_img=7).eval()
    out = tta([torch.rand(3, 32, 48), torch.rand(3, 40, 24)])
    for det, (h, w) in zip(out, [(32, 48), (40, 24)], strict=True):
        assert det["boxes"].shape == (7, 4) and det["scores"].shape == (7,)
        assert bool((det["scores"][:-1] >= det["scores"][1:]).all())
        assert bool(
            (det["boxes"][:, 2] <= w + 1e-4).all() and (det["boxes"][:, 3] <= h + 1e-4).all()
        )
    model.score_thresh = 1.0  # nothing survives any view
    empty = tta([torch.rand(3, 32, 32)])[0]
    assert empty["boxes"].shape == (0, 4) and empty["scores"].shape == (0,)
    with pytest.raises(InputError, match="only predicts"):
        tta.train()([torch.rand(3, 32, 32)])
    with pytest.raises(InputError, match="views"):
        TestTimeAugmentation(model, "rotations")


@pytest.mark.parametrize("views", ["identity", "hflip", "dihedral"])
def test_tta_scales_map_back_onto_the_original_box(views):
    """The bright box seen in copies scaled by 0.5, 1 and 2 (even factors on an
    image of even sides: the resized box edges land on whole pixels, so the detector
    stand-in is exact there) comes back as the original box in every view."""
    from robopercept.nn.detection.tta import TestTimeAugmentation

    image = torch.zeros(3, 20, 32)
    image[:, 4:12, 6:24] = 1.0  # box (6, 4, 24, 12): even edges, halved exactly
    tta = TestTimeAugmentation(_BrightBox(), views, scales=(0.5, 1.0, 2.0)).eval()
    out = tta([image])[0]
    torch.testing.assert_close(out["boxes"], torch.tensor([[6.0, 4.0, 24.0, 12.0]]))
    assert out["scores"].tolist() == pytest.approx([0.9])  # every view and scale saw it


def test_rescale_image_sizes_factors_and_antialias():
    from robopercept.nn.detection.tta import rescale_image

    image = torch.rand(3, 30, 41)
    same, f = rescale_image(image, 1.0)
    assert same is image and f.tolist() == [1.0, 1.0, 1.0, 1.0]
    small, f = rescale_image(image, 0.9)
    # round(30 * 0.9) = 27, round(41 * 0.9) = 36.9 -> 37: the factors are the sizes' own
    assert small.shape == (3, 27, 37)
    torch.testing.assert_close(f, torch.tensor([37 / 41, 27 / 30, 37 / 41, 27 / 30]))
    # a constant image stays constant (bilinear and its antialiased shrink both average)
    flat, _ = rescale_image(torch.full((3, 30, 41), 0.25), 0.8)
    torch.testing.assert_close(flat, torch.full_like(flat, 0.25))
    big, f = rescale_image(image, 1.1)
    assert big.shape == (3, 33, 45) and big.dtype == image.dtype


def test_resolve_tta_overrides_the_stored_configuration_option_by_option():
    from robopercept.nn.detection.tta import resolve_tta

    stored = {"views": "flips", "scales": [0.9, 1.0, 1.1], "iou_thresh": 0.55}
    assert resolve_tta(stored) == {"views": "flips", "scales": (0.9, 1.0, 1.1), "iou_thresh": 0.55}
    assert resolve_tta(stored, "hflip")["scales"] == (0.9, 1.0, 1.1)
    assert resolve_tta(stored, scales=[1.0])["views"] == "flips"
    assert resolve_tta(stored, "none") is None
    assert resolve_tta(None) is None and resolve_tta(None, "identity") is None
    assert resolve_tta(None, "hflip") == {"views": "hflip", "scales": (1.0,), "iou_thresh": None}
    assert resolve_tta(None, scales=[2, 1])["scales"] == (2.0, 1.0)
    with pytest.raises(InputError, match=r"--tta-scales needs .*drop --tta none"):
        resolve_tta(stored, "none", [1.0])
    with pytest.raises(InputError, match=r"tta \(--tta\) must be one of"):
        resolve_tta(None, "rotations")
    for bad in ([], [1.0, 1.0], [0.1], [5.0], ["x"], 3):
        with pytest.raises(InputError, match="--tta-scales"):
            resolve_tta(None, "hflip", bad)


def test_choose_tta_takes_the_best_validation_ap_and_none_when_it_does_not_help():
    """A detector exact in every view ties everywhere, and the tie goes to no
    augmentation (fewest passes); one that misplaces boxes in mirrored views makes the
    view sets with mirrors worse, and no augmentation is chosen."""
    from robopercept.nn.detection.data import DetectionDataset
    from robopercept.nn.detection.tta import TTA_GRID, choose_tta

    images, boxes = [], []
    for k in range(3):
        im = torch.zeros(3, 40, 48)
        x0, y0 = 4 + 5 * k, 6 + 3 * k
        im[:, y0 : y0 + 12, x0 : x0 + 16] = 1.0
        images.append(im.permute(1, 2, 0).numpy())
        boxes.append([[x0, y0, x0 + 16, y0 + 12]])
    ds = DetectionDataset(images, boxes, [[1]] * 3, ["bright"])

    class Shifted(_BrightBox):
        def forward(self, images):
            out = super().forward(images)
            for im, d in zip(images, out, strict=True):
                if float(im[0, :, :24].sum()) < float(im[0, :, 24:].sum()):  # mirrored
                    d["boxes"] = d["boxes"] + torch.tensor([6.0, 0, 6, 0])
            return out

    grid = [g for g in TTA_GRID if g["scales"] == (1.0,)]
    config, table = choose_tta(_BrightBox(), ds, grid)
    assert config is None and table[0]["passes"] == 1 and table[0]["AP"] == 1.0
    assert len(table) == 1 + len(grid)
    config, table = choose_tta(Shifted(), ds, grid)
    mirrored = [r for r in table if r["config"] and r["config"]["views"] in ("hflip", "flips")]
    # half or more of their views misplace the box: a worse AP; dihedral's quarter turns
    # outvote the mirrors, so it ties with none (and the tie goes to one pass)
    assert config is None and len(mirrored) == 4 and all(r["AP"] < 0.8 for r in mirrored)
    with pytest.raises(InputError, match="DetectionDataset"):
        choose_tta(_BrightBox(), [1, 2, 3])
