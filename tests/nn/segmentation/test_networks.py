"""Segmentation networks and losses (issue 27): shapes for any image size, the
transposed-convolution upsampler equal to the foundation's NumPy conv_transpose2d and to
torch's, its bilinear initialisation, receptive fields, losses against hand
computations, refusals."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
from torch.nn import functional as F  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn import functional as nf  # noqa: E402
from robopercept.nn.segmentation.networks import (  # noqa: E402
    FCN,
    NaiveFCN,
    UNet,
    bilinear_kernel,
    build_segmenter,
    dice_loss,
    predict_segmentation,
    segmentation_cross_entropy,
)

pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.mark.parametrize("upsample", ["transposed", "bilinear"])
@pytest.mark.parametrize("name", ["naive", "fcn32s", "fcn16s", "fcn8s", "unet"])
def test_logits_have_the_image_size_for_any_size(name, upsample):
    torch.manual_seed(0)
    kw = {} if name == "naive" else {"upsample": upsample}
    net = build_segmenter(name, 3, width=4, **kw).eval()
    for h, w in ((32, 32), (37, 50), (9, 70)):
        assert net(torch.rand(2, 3, h, w)).shape == (2, 3, h, w)


def test_transposed_convolution_equals_numpy_and_torch():
    rng = np.random.default_rng(0)
    for stride, pad, k in ((2, 1, 4), (8, 4, 16), (3, 1, 5), (2, 0, 3)):
        x = rng.standard_normal((2, 3, 5, 6))
        w = rng.standard_normal((3, 4, k, k))
        ours = nf.conv_transpose2d(x, w, stride=stride, padding=pad)
        ref = F.conv_transpose2d(
            torch.from_numpy(x), torch.from_numpy(w), stride=stride, padding=pad
        ).numpy()
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)
    # the FCN upsampler's layer computes the same
    net = FCN(2, "32s", width=4)
    up = net.up_final.conv
    x = torch.randn(1, 2, 3, 4)
    np.testing.assert_allclose(
        up(x).detach().numpy(),
        nf.conv_transpose2d(x.numpy(), up.weight.detach().numpy(), stride=32, padding=16),
        rtol=0,
        atol=1e-5,
    )


@pytest.mark.parametrize("factor", [2, 4, 8])
def test_bilinear_initialisation_is_bilinear_interpolation_inside(factor):
    # away from the border (where the transposed convolution sees zeros and
    # interpolation repeats the edge) the initial upsampler is bilinear interpolation
    x = torch.rand(1, 2, 6, 7, dtype=torch.float64)
    k = 2 * factor - factor % 2
    w = bilinear_kernel(2, factor).double()
    up = F.conv_transpose2d(x, w, stride=factor, padding=(k - factor) // 2)
    ref = F.interpolate(x, scale_factor=factor, mode="bilinear", align_corners=False)
    m = factor
    torch.testing.assert_close(up[..., m:-m, m:-m], ref[..., m:-m, m:-m], rtol=0, atol=1e-12)
    # and it does not mix channels
    assert w[0, 1].abs().sum() == 0 and w[1, 0].abs().sum() == 0


def _reach(net: torch.nn.Module, size: int) -> int:
    """How far (in pixels) from the centre the input moves the centre output."""
    net.eval()
    torch.manual_seed(0)  # a random image: at zero every ReLU sits at its kink
    x = torch.rand(1, net.in_channels, size, size, requires_grad=True)
    (g,) = torch.autograd.grad(net(x)[0, :, size // 2, size // 2].sum(), x)
    ys, xs = torch.nonzero(g.abs().sum((0, 1)) > 0, as_tuple=True)
    return int(max((ys - size // 2).abs().max(), (xs - size // 2).abs().max()))


def test_receptive_fields_naive_small_unet_large():
    # depth 3 x 3 convolutions reach `depth` pixels; a 3-level U-Net reaches far more
    assert _reach(NaiveFCN(2, width=16, depth=3), 31) == 3
    assert _reach(NaiveFCN(2, width=16, depth=6), 31) == 6
    assert _reach(UNet(2, width=8, depth=3), 64) > 20


def test_cross_entropy_weights_and_ignore_by_hand():
    logits = torch.tensor([[[[2.0, 0.0]], [[0.0, 1.0]]]])  # (1, 2, 1, 2)
    target = torch.tensor([[[0, 1]]])
    lp = logits.log_softmax(1)
    nll = torch.stack([-lp[0, 0, 0, 0], -lp[0, 1, 0, 1]])
    assert segmentation_cross_entropy(logits, target) == pytest.approx(float(nll.mean()))
    w = torch.tensor([1.0, 3.0])
    want = float((nll[0] + 3 * nll[1]) / 4)
    assert segmentation_cross_entropy(logits, target, weight=w) == pytest.approx(want)
    ig = torch.tensor([[[0, 255]]])
    assert segmentation_cross_entropy(logits, ig, ignore_index=255) == pytest.approx(float(nll[0]))
    every = torch.full((1, 1, 2), 255)
    assert float(segmentation_cross_entropy(logits, every, ignore_index=255)) == 0.0


def test_dice_loss_by_hand():
    target = torch.tensor([[[0, 1], [1, 1]]])
    perfect = F.one_hot(target, 2).permute(0, 3, 1, 2).float() * 50
    assert float(dice_loss(perfect, target, eps=1e-6)) == pytest.approx(0.0, abs=1e-6)
    # uniform logits: P = 1/2 everywhere; class 0: 2 * 0.5 / (2 + 1), class 1: 2 * 1.5 / (2 + 3)
    flat = torch.zeros(1, 2, 2, 2)
    want = 1 - (1 / 3 + 3 / 5) / 2
    assert float(dice_loss(flat, target, eps=1e-9)) == pytest.approx(want, abs=1e-7)
    # an ignored pixel counts on neither side: with pixel (0, 0) ignored, class 0 has
    # no true pixel and 3 x 0.5 predicted (score ~0), class 1: 2 * 1.5 / (1.5 + 3)
    ig = torch.tensor([[[255, 1], [1, 1]]])
    want = 1 - (0.0 + 2 * 1.5 / (1.5 + 3)) / 2
    assert float(dice_loss(flat, ig, ignore_index=255, eps=1e-9)) == pytest.approx(want, abs=1e-6)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: build_segmenter("segnet", 2), "name"),
        (lambda: FCN(2, "4s"), "variant"),
        (lambda: FCN(2, in_channels=1), "RGB"),
        (lambda: UNet(2, upsample="nearest"), "upsample"),
        (lambda: UNet(2, width=1024, depth=4), "lower the width"),
        (lambda: UNet(2, in_channels=1)(torch.zeros(1, 3, 8, 8)), "1 input channel"),
        (lambda: FCN(2, width=4)(torch.zeros(1, 3, 20, 30)), "batches of 2"),
        (
            lambda: segmentation_cross_entropy(torch.zeros(1, 2, 2, 2), torch.full((1, 2, 2), 2)),
            "label 2, outside the 2 classes",
        ),
        (
            lambda: segmentation_cross_entropy(
                torch.zeros(1, 2, 2, 2), torch.zeros(1, 3, 2).long()
            ),
            r"need \(1, 2, 2\)",
        ),
        (
            lambda: dice_loss(torch.zeros(1, 2, 2, 2), torch.zeros(1, 2, 2)),
            "integer",
        ),
        (
            lambda: segmentation_cross_entropy(
                torch.zeros(1, 2, 1, 1), torch.zeros(1, 1, 1).long(), weight=torch.ones(3)
            ),
            "2 finite class weights",
        ),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


def _squares(n: int, size: int = 16, seed: int = 0):
    """Bright squares on a noisy dark ground; the mask is the square."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 0.3, (n, size, size, 1)).astype(np.float32)
    y = np.zeros((n, size, size), np.int64)
    for i in range(n):
        r, c = rng.integers(0, size - 6, 2)
        s = int(rng.integers(4, 7))
        x[i, r : r + s, c : c + s] += 0.6
        y[i, r : r + s, c : c + s] = 1
    return x, y


def test_train_segmenter_learns_keeps_the_best_epoch_and_repeats():
    from robopercept.nn.segmentation.metrics import segmentation_confusion, segmentation_scores
    from robopercept.nn.segmentation.networks import predict_segmentation, train_segmenter
    from robopercept.nn.train.config import TrainConfig

    x, y = _squares(24)
    vx, vy = _squares(8, seed=1)
    cfg = TrainConfig(epochs=12, batch_size=8, lr=1e-2, device="cpu", seed=0)

    def run():
        torch.manual_seed(0)
        net = UNet(2, in_channels=1, width=4, depth=2)
        return net, train_segmenter(net, x, y, cfg, val=(vx, vy), crop=12, progress=False)

    net, hist = run()
    assert len(hist.losses) == 12 and hist.losses[-1] < hist.losses[0]
    assert max(hist.val.values()) > 0.9  # a separable task is learnt
    # the weights kept are the best epoch's: scoring them again gives its mIoU
    assert hist.val[hist.best_epoch] == max(hist.val.values())
    pred = predict_segmentation(net, vx).numpy()
    again = segmentation_scores(segmentation_confusion(vy, pred, 2)).miou
    assert again == pytest.approx(hist.val[hist.best_epoch], abs=1e-12)
    # seeded: a second run repeats every loss
    _, hist2 = run()
    assert hist2.losses == hist.losses


def test_train_segmenter_ignore_index_weights_and_refusals():
    from robopercept.nn.segmentation.networks import train_segmenter
    from robopercept.nn.train.config import TrainConfig

    x, y = _squares(4)
    y[:, 0, :] = 255  # a void row
    net = UNet(2, in_channels=1, width=4, depth=2)
    cfg = TrainConfig(epochs=1, batch_size=2, device="cpu")
    h = train_segmenter(
        net, x, y, cfg, ignore_index=255, class_weights=[1.0, 3.0], loss="ce", progress=False
    )
    assert len(h.losses) == 1 and np.isfinite(h.losses[0])
    with pytest.raises(InputError, match="label 255"):
        train_segmenter(net, x, y, cfg, progress=False)  # 255 not declared void
    with pytest.raises(InputError, match="crop 20 is larger"):
        train_segmenter(net, x, y, cfg, crop=20, ignore_index=255, progress=False)
    with pytest.raises(InputError, match="loss"):
        train_segmenter(net, x, y, cfg, loss="focal", progress=False)
    with pytest.raises(InputError, match=r"\(N, H, W, C\)"):
        train_segmenter(net, x[0], y, cfg, progress=False)
    with pytest.raises(InputError, match="masks must be"):
        train_segmenter(net, x, y[:, :8], cfg, progress=False)
    bad = x.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        train_segmenter(net, bad, y, cfg, ignore_index=255, progress=False)


# ----------------------------------------------------------------------------- io
def test_save_and_load_segmenter_round_trip_and_refuse_other_checkpoints(tmp_path):
    from robopercept.errors import FileFormatError
    from robopercept.nn.detection.zoo import build_detector, save_detector
    from robopercept.nn.segmentation.networks import load_segmenter, save_segmenter, segment_arrays

    torch.manual_seed(0)
    net = build_segmenter("fcn8s", 3, width=4)
    save_segmenter(tmp_path / "s.pt", net, "fcn8s", {"width": 4}, ["a", "b"], data="x")
    back, info = load_segmenter(tmp_path / "s.pt")
    assert info["classes"] == ["a", "b"] and info["data"] == "x" and not back.training
    for (k, a), b in zip(net.state_dict().items(), back.state_dict().values(), strict=True):
        assert torch.equal(a, b), k
    img = np.random.default_rng(0).uniform(0, 1, (24, 40, 3)).astype(np.float32)
    np.testing.assert_array_equal(segment_arrays(net, [img])[0], segment_arrays(back, [img])[0])
    save_detector(tmp_path / "d.pt", build_detector("fcos", 2, width=4), "fcos", {}, ["a", "b"])
    with pytest.raises(FileFormatError, match="not a segmenter checkpoint"):
        load_segmenter(tmp_path / "d.pt")
    with pytest.raises(InputError, match="name"):
        save_segmenter(tmp_path / "t.pt", net, "resnet", {}, ["a"])
    with pytest.raises(InputError, match="classes"):
        save_segmenter(tmp_path / "t.pt", net, "fcn8s", {}, [])


def test_segment_arrays_converts_images_for_the_network():
    from robopercept.nn.segmentation.networks import segment_arrays

    torch.manual_seed(0)
    grey_net = UNet(2, in_channels=1, width=4, depth=2)
    rgb = np.random.default_rng(1).integers(0, 256, (16, 20, 3)).astype(np.uint8)
    # a one-channel network sees the channel mean of the unit-scaled image
    mean = (rgb / 255.0).mean(axis=2, keepdims=True).astype(np.float32)[None]
    want = predict_segmentation(grey_net, mean)[0].numpy()
    np.testing.assert_array_equal(segment_arrays(grey_net, [rgb])[0], want)
    # a grey image through a three-channel network is repeated into RGB
    net = UNet(3, width=4, depth=2)
    grey = rgb[..., 0]
    rep = np.repeat((grey / 255.0)[..., None], 3, axis=2).astype(np.float32)[None]
    np.testing.assert_array_equal(
        segment_arrays(net, [grey])[0], predict_segmentation(net, rep)[0].numpy()
    )
    with pytest.raises(InputError, match="images\\[0\\]"):
        segment_arrays(net, [np.zeros((4, 4, 2))])
    with pytest.raises(InputError, match="segmenter"):
        segment_arrays(torch.nn.Linear(2, 2), [grey])


def test_coco_segmentation_results_round_trip_the_masks():
    from robopercept.nn.coco.rle import rle_decode
    from robopercept.nn.segmentation.networks import coco_segmentation_results

    lab = np.zeros((6, 7), np.int64)
    lab[1:3, 2:5] = 2
    lab[4:, :2] = 4
    res = coco_segmentation_results(5, labels=lab)
    assert [r["category_id"] for r in res] == [2, 4] and all(r["image_id"] == 5 for r in res)
    for r in res:
        np.testing.assert_array_equal(rle_decode(r["segmentation"]), lab == r["category_id"])
    masks = np.stack([lab == 2, lab == 4])
    det = {
        "boxes": np.array([[2.0, 1, 5, 3], [0, 4, 2, 6]]),
        "labels": np.array([1, 3]),
        "scores": np.array([0.9, 0.6]),
        "masks": masks,
    }
    res = coco_segmentation_results(1, detections=det)
    assert [r["bbox"] for r in res] == [[2.0, 1.0, 3.0, 2.0], [0.0, 4.0, 2.0, 2.0]]
    assert [r["score"] for r in res] == [0.9, 0.6]
    for r, m in zip(res, masks, strict=True):
        np.testing.assert_array_equal(rle_decode(r["segmentation"]).astype(bool), m)
    with pytest.raises(InputError, match="either labels"):
        coco_segmentation_results(1)
    with pytest.raises(InputError, match="no 'masks'"):
        coco_segmentation_results(1, detections={k: v for k, v in det.items() if k != "masks"})


def test_segmentation_sets_split_the_builtin_data():
    from robopercept.nn.segmentation.data import segmentation_sets

    s = segmentation_sets("shapes", 10, (48, 40), seed=2)
    assert len(s.train) == 8 and len(s.val) == 2 and s.classes == s.train.classes
    assert s.train.images[0].shape == (40, 48, 3) and s.val.class_maps().shape == (2, 40, 48)
    again = segmentation_sets("shapes", 10, (48, 40), seed=2)
    np.testing.assert_array_equal(again.val.images[0], s.val.images[0])
    d = segmentation_sets("digits", 4, (64, 64), seed=0)
    assert d.classes[0] == "0" and d.train.masks is not None
    with pytest.raises(InputError, match="one of shapes"):
        segmentation_sets("coco")
    with pytest.raises(InputError, match="folder"):
        segmentation_sets("nuclei")
    with pytest.raises(InputError, match="n_images"):
        segmentation_sets("shapes", 1)
