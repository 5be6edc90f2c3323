"""Make the pictures of docs/pointcloud_dl.md.

Run from the repository root (about a minute on 2 cores; the networks are read from
MODELS)::

    python docs/make_cloud_pictures.py [MODELS [DATA]]

MODELS is the folder of ``python -m benchmarks.cloud_figures --only pointnet dgcnn
pointnet-parts --seeds 0 --save MODELS`` (default ``src/robopercept/data``, where the
shipped networks are); DATA the shared data folder (default ``../shared/data``). Writes
to docs/img/:

- cloud_shapes.png: one procedural shape of each class, coloured by its parts;
- cloud_variants.png: the same shapes clean, as partial views and with strong noise;
- cloud_critical.png: PointNet's critical point set of a test shape;
- cloud_neighbours.png: DGCNN's k-NN neighbourhoods of three points at each layer
  (xyz first, then feature space);
- cloud_parts.png: the PointNet part segmenter on test shapes (truth / prediction);
- cloud_confusion.png: the PointNet classifier's confusion matrix on the test shapes;
- cloud_modelnet.png: the real ModelNet meshes, sampled, with the classifier's
  (out-of-domain) answer.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

from robopercept.imaging import write_image
from robopercept.nn.cloud.pointnet import critical_points
from robopercept.nn.cloud.run import classify_cloud_file
from robopercept.nn.cloud.synthetic import SHAPE_CLASSES, procedural_shapes
from robopercept.nn.cloud.train import evaluate_cloud_model, load_cloud_model
from robopercept.viz.cloud_dl import (
    clouds_grid,
    critical_points_picture,
    feature_neighbours_picture,
)
from robopercept.viz.learning import confusion_picture

OUT = Path("docs/img")


def main(models: Path, data: Path) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    one = procedural_shapes(1, 1024, rng=5)
    write_image(
        OUT / "cloud_shapes.png",
        clouds_grid(
            list(one.points),
            list(SHAPE_CLASSES),
            [p for p in one.parts] if one.parts is not None else None,
            columns=6,
            size=(1800, 800),
        ),
    )
    picks = ["table", "mug", "l_shape", "cylinder"]
    clouds, titles = [], []
    for variant in ("clean", "partial", "noisy"):
        ds = procedural_shapes(1, 1024, classes=picks, variant=variant, rng=7)
        clouds += list(ds.points)
        titles += [f"{c} ({variant})" for c in picks]
    write_image(
        OUT / "cloud_variants.png", clouds_grid(clouds, titles, columns=4, size=(1800, 1200))
    )

    pointnet, pinfo = load_cloud_model(models / "cloud_pointnet_shapes.pt")
    test = procedural_shapes(25, pinfo["n_points"], rng=99)
    cls = list(pinfo["class_names"])
    table = test.points[cls.index("table") * 25]
    crit = critical_points(pointnet, table)
    write_image(
        OUT / "cloud_critical.png",
        critical_points_picture(table, crit, title="PointNet's critical point set (a table)"),
    )
    ev = evaluate_cloud_model(pointnet, test)
    write_image(
        OUT / "cloud_confusion.png",
        confusion_picture(
            ev.confusion, cls, title=f"PointNet, test shapes: accuracy {ev.accuracy:.3f}"
        ),
    )

    dgcnn, dinfo = load_cloud_model(models / "cloud_dgcnn_shapes.pt")
    small = procedural_shapes(1, dinfo["n_points"], classes=["table"], rng=99)
    with torch.no_grad():
        out = dgcnn.forward_aux(torch.from_numpy(small.points[:1]))
    graphs = [g[0].numpy() for g in out.graphs]
    pts = small.points[0]
    # how far each layer's neighbourhoods are from the xyz ones, over test shapes
    many = procedural_shapes(3, dinfo["n_points"], rng=99)
    with torch.no_grad():
        all_graphs = [g.numpy() for g in dgcnn.forward_aux(torch.from_numpy(many.points)).graphs]
    b = np.arange(len(many))[:, None, None]
    for layer, g in enumerate(all_graphs, 1):
        same = (g[..., :, None] == all_graphs[0][..., None, :]).any(-1).mean()
        spread = np.linalg.norm(many.points[b, g] - many.points[:, :, None], axis=-1).mean()
        print(
            f"layer {layer}: {same:.3f} of the neighbours are xyz neighbours, "
            f"mean neighbour distance {spread:.3f} (unit sphere)"
        )
    # the queries: the three points whose last-layer neighbourhood is widest, apart
    widest = np.linalg.norm(pts[graphs[-1]] - pts[:, None], axis=-1).mean(1)
    queries: list[int] = []
    for i in np.argsort(-widest):
        if all(np.linalg.norm(pts[i] - pts[j]) > 0.5 for j in queries):
            queries.append(int(i))
        if len(queries) == 3:
            break
    write_image(
        OUT / "cloud_neighbours.png",
        feature_neighbours_picture(pts, graphs, np.array(queries), size=(1800, 520)),
    )

    parts_path = models / "cloud_pointnet_parts.pt"
    if parts_path.is_file():
        seg, sinfo = load_cloud_model(parts_path)
        # one test shape of every class (the segmenter takes the true category)
        full = procedural_shapes(1, sinfo["n_points"], rng=99)
        assert full.parts is not None
        rows = [cls.index(c) for c in picks]
        pred = evaluate_cloud_model(seg, full).predictions[rows]
        clouds = [*full.points[rows], *full.points[rows]]
        titles = [f"{c}: truth" for c in picks] + [f"{c}: predicted" for c in picks]
        write_image(
            OUT / "cloud_parts.png",
            clouds_grid(
                clouds,
                titles,
                [*full.parts[rows], *pred],
                columns=4,
                size=(1800, 900),
            ),
        )

    meshes = sorted((data / "pointcloud_cls").rglob("*.off"))[:8]
    if meshes:
        clouds, titles = [], []
        for m in meshes:
            res = classify_cloud_file(m, pointnet, pinfo)
            clouds.append(res.points)
            folder = m.parent.parent if m.parent.name in ("train", "test") else m.parent
            titles.append(f"{folder.name} -> {res.label}")
        write_image(
            OUT / "cloud_modelnet.png", clouds_grid(clouds, titles, columns=4, size=(1800, 900))
        )


if __name__ == "__main__":
    models = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("src/robopercept/data")
    data = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("../shared/data")
    main(models, data)
