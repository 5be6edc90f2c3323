"""Make the pictures of docs/segmentation.md.

Run from the repository root (about five minutes on 2 cores: the nuclei models are
trained here, the shapes models are read from MODELS)::

    python docs/make_segmentation_pictures.py [MODELS [NUCLEI]]

MODELS is the folder of ``python -m benchmarks.segmentation_figures --only shapes-unet
shapes-fcn32s shapes-naive shapes-maskrcnn --seeds 0 --save MODELS`` (default
``src/robopercept/data``, where the shipped U-Net and Mask R-CNN are; the FCN-32s and
naive panels are left out when their files are absent); NUCLEI the stardist_nuclei
folder (default ``../shared/data/segmentation/stardist_nuclei``). Writes to docs/img/:

- segmentation_checkerboard.png: a constant map upsampled x2 by a 3 x 3 stride-2
  transposed convolution of ones (uneven overlap: the checkerboard), by FCN's 4 x 4
  kernel initialised to bilinear interpolation (even overlap) and by bilinear
  interpolation;
- segmentation_receptive_fields.png: where the centre output of the naive network,
  FCN-32s and U-Net (untrained, seeded) depends on a 128 x 128 input (the gradient's
  support, log scale);
- segmentation_shapes.png: the semantic networks and Mask R-CNN on test canvases of
  the procedural set, beside the ground truth;
- segmentation_nuclei.png: U-Net and Mask R-CNN trained on three quadrants of the
  real nuclei image, on the held-out quadrant, beside the ground truth.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch
from robopercept.nn.segmentation.data import nuclei_quadrants
from torch.nn import functional as F

from benchmarks.segmentation_figures import nuclei_maskrcnn_model, nuclei_unet_model
from robopercept.imaging import label_components, write_image
from robopercept.nn.detection.synthetic import procedural_detection_set
from robopercept.nn.detection.zoo import detect_arrays, load_detector
from robopercept.nn.segmentation.networks import (
    FCN,
    NaiveFCN,
    UNet,
    bilinear_kernel,
    load_segmenter,
    segment_arrays,
)
from robopercept.viz.colormap import turbo
from robopercept.viz.segmentation import class_overlay, instance_overlay, panels_picture

IMG = Path(__file__).resolve().parent / "img"
NUCLEI = "../shared/data/segmentation/stardist_nuclei"


def _gray(field: np.ndarray, side: int = 256) -> np.ndarray:
    """A scalar map stretched to 0..255 and enlarged to about ``side`` pixels."""
    lo, hi = float(field.min()), float(field.max())
    g = np.zeros_like(field) if hi <= lo else (field - lo) / (hi - lo)
    g8 = np.round(g * 255).astype(np.uint8)
    f = max(1, side // max(field.shape))
    return np.repeat(np.repeat(np.repeat(g8[..., None], 3, 2), f, 0), f, 1)


def checkerboard() -> None:
    x = torch.ones(1, 1, 12, 12)
    ones = F.conv_transpose2d(x, torch.ones(1, 1, 3, 3), stride=2)
    fcn = F.conv_transpose2d(x, bilinear_kernel(1, 2), stride=2, padding=1)
    bil = F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)
    pics, titles = [], []
    for name, y in (
        ("3x3 stride 2, ones", ones),
        ("4x4 stride 2, bilinear init", fcn),
        ("bilinear interpolation", bil),
    ):
        inner = y[0, 0, 4:-4, 4:-4].numpy()
        pics.append(_gray(y[0, 0].numpy()))
        titles.append(f"{name}: std {inner.std():.2f}")
    write_image(IMG / "segmentation_checkerboard.png", panels_picture(pics, titles))


def receptive_fields() -> None:
    torch.manual_seed(0)
    nets = {
        "naive (6 layers)": NaiveFCN(5, width=16, depth=6),
        "FCN-32s": FCN(5, width=8, variant="32s"),
        "U-Net (depth 4)": UNet(5, width=8, depth=4),
    }
    pics, titles = [], []
    for name, net in nets.items():
        net.eval()
        x = torch.rand(1, 3, 128, 128, requires_grad=True)
        net(x)[0, :, 64, 64].sum().backward()
        g = x.grad.abs().sum(1)[0].numpy()
        rows, cols = np.nonzero(g > 0)
        extent = (rows.max() - rows.min() + 1, cols.max() - cols.min() + 1)
        heat = turbo(np.log10(g + 1e-12).clip(-8, None) / 8 + 1)
        heat[g == 0] = 0
        pics.append(np.repeat(np.repeat(heat, 3, 0), 3, 1))
        titles.append(f"{name}: {extent[1]} x {extent[0]} px")
    write_image(IMG / "segmentation_receptive_fields.png", panels_picture(pics, titles))


def shapes(models: Path) -> None:
    test = procedural_detection_set(3, (128, 128), rng=99)
    truth = test.class_maps()
    names = list(test.classes)
    rows = []
    for i in range(2):
        pics = [class_overlay(test.images[i], truth[i], names)]
        titles = ["ground truth"]
        for label, file in (
            ("U-Net", "segmenter_unet_shapes.pt"),
            ("FCN-32s", "segmenter_fcn32s_shapes.pt"),
            ("naive", "segmenter_naive_shapes.pt"),
        ):
            if (models / file).is_file():
                net, _ = load_segmenter(models / file)
                pics.append(
                    class_overlay(test.images[i], segment_arrays(net, [test.images[i]])[0], names)
                )
                titles.append(label)
        if (models / "segmenter_maskrcnn_shapes.pt").is_file():
            mr, _ = load_detector(models / "segmenter_maskrcnn_shapes.pt")
            d = detect_arrays(mr, [test.images[i]])[0]
            keep = d["scores"] >= 0.5
            pics.append(
                instance_overlay(
                    test.images[i],
                    d["masks"][keep],
                    labels=d["labels"][keep],
                    classes=names,
                    scores=d["scores"][keep],
                )
            )
            titles.append("Mask R-CNN")
        rows.append(panels_picture(pics, titles))
    w = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 12), (0, w - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    write_image(IMG / "segmentation_shapes.png", np.concatenate(rows, 0))


def nuclei(folder: Path) -> None:
    s = nuclei_quadrants(folder)
    unet = nuclei_unet_model(0, False)[0]
    mr = nuclei_maskrcnn_model(0, False)[0]
    image = np.clip(s.test_image[..., 0], 0, 1)
    fg = segment_arrays(unet, [image])[0] == 1
    components, _ = label_components(fg, connectivity=4)
    d = detect_arrays(mr, [np.repeat(image[..., None], 3, 2)])[0]
    keep = d["scores"] >= 0.5
    pics = [
        instance_overlay(image, s.test_instances, min_side=768),
        instance_overlay(image, components, min_side=768),
        instance_overlay(image, d["masks"][keep], min_side=768),
    ]
    titles = ["ground truth (29 nuclei)", "U-Net + connected components", "Mask R-CNN"]
    write_image(IMG / "segmentation_nuclei.png", panels_picture(pics, titles))


def main() -> None:
    models = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("src/robopercept/data")
    folder = Path(
        sys.argv[2] if len(sys.argv) > 2 else "../shared/data/segmentation/stardist_nuclei"
    )
    torch.set_num_threads(2)
    checkerboard()
    receptive_fields()
    shapes(models)
    if folder.is_dir():
        nuclei(folder)


if __name__ == "__main__":
    main()
