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
