"""Tests of robopercept.nn.cloud.dgcnn: the k-NN graph against SciPy's cKDTree, EdgeConv against
PyTorch Geometric and the reference formulation, and the DGCNN model (shapes, masks,
permutation invariance, errors, config round trips)."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from scipy.spatial import cKDTree  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.cloud.dgcnn import DGCNN, CloudOutput, EdgeConv, edge_features, knn_graph  # noqa: E402
from robopercept.nn.cloud.pointnet import MaskedBatchNorm  # noqa: E402
from tests.conftest import data_path  # noqa: E402

TINY = {"k": 4, "widths": (8, 8), "embedding": 16}


def tiny(task: str = "classify", **kw) -> DGCNN:
    torch.manual_seed(0)
    return randomize_norms(DGCNN(kw.pop("num_outputs", 4), task=task, **{**TINY, **kw})).eval()


def randomize_norms(model):
    """Batch-norm parameters and statistics away from their initial 1, 0: a zero
    (padded) point then has non-zero features, so masking is put to the test."""
    g = torch.Generator().manual_seed(11)
    for mod in model.modules():
        if isinstance(mod, MaskedBatchNorm):
            c = mod.num_features
            with torch.no_grad():
                mod.weight.copy_(torch.rand(c, generator=g) + 0.5)
                mod.bias.copy_(torch.rand(c, generator=g) - 0.5)
                mod.running_mean.copy_(torch.rand(c, generator=g) * 0.4 - 0.2)
                mod.running_var.copy_(torch.rand(c, generator=g) * 1.5 + 0.5)
    return model


def cloud(b: int = 2, n: int = 40, c: int = 3, seed: int = 0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(b, n, c, generator=g, dtype=torch.float64) * 2 - 1).to(dtype)


def padded(lengths: list[int], n: int, seed: int = 1, fill: float = 0.0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    clouds = [torch.rand(m, 3, generator=g, dtype=torch.float64).to(dtype) for m in lengths]
    x = torch.full((len(lengths), n, 3), fill, dtype=dtype)
    mask = torch.zeros(len(lengths), n, dtype=torch.bool)
    for i, c in enumerate(clouds):
        x[i, : len(c)] = c
        mask[i, : len(c)] = True
    return x, mask, clouds


class TestKnnGraph:
    def test_hand_case(self):
        x = torch.tensor([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [3.5, 0.0], [10.0, 0.0]])
        assert knn_graph(x, 3).tolist() == [
            [0, 1, 2],
            [1, 0, 2],
            [2, 3, 1],
            [3, 2, 1],
            [4, 3, 2],
        ]

    @pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
    def test_matches_ckdtree(self, dtype):
        x = cloud(1, 3000, 3, seed=5, dtype=dtype)[0] + 50.0  # an offset cloud
        got = knn_graph(x, 16).numpy()
        pts = x.double().numpy()  # the same (float32) points, searched in float64
        want = cKDTree(pts).query(pts, 16)[1]
        # random data has no ties: the very same indices in the same order
        np.testing.assert_array_equal(got, want)

    def test_large_cloud_in_chunks(self):
        """20,000 points (a 1.6 GB distance matrix unchunked) in 64 MB blocks, float32,
        exact against cKDTree: the expansion alone swaps near neighbours at this size,
        the refinement puts them back."""
        x = torch.rand(20_000, 3, generator=torch.Generator().manual_seed(1))
        got = knn_graph(x, 8).numpy()
        pts = x.double().numpy()
        want = cKDTree(pts).query(pts, 8)[1]
        np.testing.assert_array_equal(got, want)

    def test_chunked_equals_unchunked(self):
        x, mask, _ = padded([300, 211, 257], 300, seed=3)
        whole = knn_graph(x, 10, mask, chunk_size=300)
        for rows in (5, 64):
            assert torch.equal(knn_graph(x, 10, mask, chunk_size=rows), whole)
        assert torch.equal(knn_graph(x, 10, mask), whole)

    def test_masked_equals_alone_and_padding_is_never_a_neighbour(self):
        x, mask, clouds = padded([50, 23], 50, fill=0.5)
        idx = knn_graph(x, 6, mask)
        for i, c in enumerate(clouds):
            m = len(c)
            assert torch.equal(idx[i, :m], knn_graph(c, 6))
            assert int(idx[i, :m].max()) < m
            own = torch.arange(m, 50)[:, None].expand(-1, 6)
            assert torch.equal(idx[i, m:], own)

    def test_high_dimensional_features(self):
        f = cloud(2, 200, 64, seed=8)
        idx = knn_graph(f, 12)
        for b in range(2):
            want = cKDTree(f[b].double().numpy()).query(f[b].double().numpy(), 12)[1]
            np.testing.assert_array_equal(idx[b].numpy(), want)

    def test_errors(self):
        x = cloud(2, 10)
        with pytest.raises(InputError, match=r"k=11.*cloud 0 has 10.*sample more points"):
            knn_graph(x, 11)
        mask = torch.ones(2, 10, dtype=torch.bool)
        mask[1, 4:] = False
        with pytest.raises(InputError, match=r"k=5.*cloud 1 has 4.*smaller k"):
            knn_graph(x, 5, mask)
        x[0, 3, 1] = float("nan")
        with pytest.raises(InputError, match=r"NaN.*isfinite"):
            knn_graph(x, 3)
        with pytest.raises(InputError, match="chunk_size"):
            knn_graph(cloud(), 3, chunk_size=0)


class TestEdgeConv:
    def test_edge_features(self):
        x = torch.tensor([[[0.0], [2.0]]])
        e = edge_features(x, torch.tensor([[[0, 1], [1, 0]]]))
        assert e.shape == (1, 2, 2, 2)
        assert e[0].tolist() == [[[0.0, 0.0], [2.0, 2.0]], [[0.0, 2.0], [0.0, -2.0]]]
        with pytest.raises(InputError, match=r"idx must hold point indices in \[0, 2\)"):
            edge_features(x, torch.tensor([[[0, 2], [1, 0]]]))

    @pytest.mark.parametrize("train", [False, True])
    def test_matches_reference_formulation(self, train):
        """Conv2d 1x1 on get_graph_feature's tensor, BatchNorm2d, LeakyReLU, max over k
        (the reference's layer), with the same weights; in training mode too."""
        torch.manual_seed(0)
        conv = EdgeConv(5, 7, k=6).train(train)
        ref_bn = torch.nn.BatchNorm2d(7).train(train)
        with torch.no_grad():
            conv.bn.weight.uniform_(-1.5, 1.5)  # negative scales too
            conv.bn.bias.uniform_(-0.5, 0.5)
            conv.bn.running_mean.uniform_(-0.2, 0.2)
            conv.bn.running_var.uniform_(0.5, 2.0)
        ref_bn.load_state_dict(conv.bn.state_dict())
        x = cloud(3, 30, 5, seed=2)
        idx = knn_graph(x, 6)
        got = conv(x, idx)
        e = edge_features(x, idx)  # (B, 2C, N, k)
        h = torch.nn.functional.conv2d(e, conv.linear.weight[:, :, None, None])
        want = torch.nn.functional.leaky_relu(ref_bn(h), 0.2).amax(-1).transpose(1, 2)
        # W [x_i, x_j - x_i] is computed as (Wa - Wb) x_i + Wb x_j: float32 rounding
        torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)
        if train:
            torch.testing.assert_close(conv.bn.running_var, ref_bn.running_var)

    def test_matches_torch_geometric(self):
        pyg = pytest.importorskip("torch_geometric.nn")
        torch.manual_seed(1)
        conv = EdgeConv(4, 6, k=5).eval()
        with torch.no_grad():
            conv.bn.weight.uniform_(-1.5, 1.5)
            conv.bn.running_mean.uniform_(-0.3, 0.3)
            conv.bn.running_var.uniform_(0.5, 2.0)
        x = cloud(2, 25, 4, seed=4)
        idx = knn_graph(x, 5)
        b, n, k = idx.shape
        # PyG's flow "source_to_target": edge_index[0] = source j, edge_index[1] = target
        # i; EdgeConv's message is nn(cat[x_i, x_j - x_i]) and "max" aggregates at i
        offset = (torch.arange(b) * n)[:, None, None]
        src = (idx + offset).flatten()
        dst = (torch.arange(n)[None, :, None].expand(b, n, k) + offset).flatten()
        h_theta = torch.nn.Sequential(conv.linear, _EvalBN(conv.bn), torch.nn.LeakyReLU(0.2))
        ref = pyg.EdgeConv(h_theta, aggr="max")
        want = ref(x.reshape(b * n, 4), torch.stack([src, dst])).reshape(b, n, 6)
        # the same function, our weights decomposed per point: float32 rounding
        torch.testing.assert_close(conv(x, idx), want, atol=1e-5, rtol=1e-5)

    def test_own_graph_and_errors(self):
        conv = EdgeConv(3, 4, k=3).eval()
        x = cloud(1, 12)
        assert torch.equal(conv(x), conv(x, knn_graph(x, 3)))
        with pytest.raises(InputError, match=r"x.transpose\(1, 2\)"):
            conv(x.transpose(1, 2), knn_graph(x, 3))
        with pytest.raises(InputError, match=r"idx.long\(\)"):
            conv(x, knn_graph(x, 3).int())


class _EvalBN(torch.nn.Module):
    """Our batch norm on PyG's (E, C) edge messages."""

    def __init__(self, bn):
        super().__init__()
        self.bn = bn

    def forward(self, h):
        return self.bn(h)


class TestDGCNN:
    def test_classify(self):
        m = tiny()
        out = m.forward_aux(cloud())
        assert isinstance(out, CloudOutput)
        assert out.logits.shape == (2, 4)
        assert out.global_feature.shape == (2, 32) == out.pooled_index.shape
        assert bool((out.pooled_index[:, :16] >= 0).all())
        assert bool((out.pooled_index[:, 16:] == -1).all())
        assert [g.shape for g in out.graphs] == [(2, 40, 4)] * 2
        assert out.transforms == []

    def test_segment_and_graphs(self):
        m = tiny("segment", num_outputs=5, num_categories=2, widths=(8, 8, 8))
        out = m.forward_aux(cloud(), category=torch.tensor([1, 0]))
        assert out.logits.shape == (2, 40, 5)
        assert torch.equal(out.graphs[0], knn_graph(cloud(), 4))
        assert not torch.equal(out.graphs[1], out.graphs[0])  # dynamic: feature space
        fixed = tiny(static_graph=True, widths=(8, 8, 8)).forward_aux(cloud())
        assert all(torch.equal(g, fixed.graphs[0]) for g in fixed.graphs)

    def test_default_config(self):
        m = DGCNN(40).eval()
        assert m(cloud(1, 64)).shape == (1, 40)
        assert m.forward_aux(cloud(1, 64)).global_feature.shape == (1, 2048)

    @pytest.mark.parametrize("masked", [False, True])
    @pytest.mark.parametrize("task", ["classify", "segment"])
    def test_permutation_invariance(self, task, masked):
        # float32; the average pool sums the points in another order: a few ulp of the
        # 16-channel embedding, well under 1e-6 in the logits
        m = tiny(task)
        x, mask, _ = padded([30, 17, 22], 30, seed=4)
        if not masked:
            x, mask = cloud(3, 30, seed=4), None
        out = m(x, mask)
        g = torch.Generator().manual_seed(7)
        for _ in range(3):
            perm = torch.randperm(30, generator=g)
            other = m(x[:, perm], None if mask is None else mask[:, perm])
            if task == "classify":
                torch.testing.assert_close(other, out, atol=1e-6, rtol=0)
            else:
                keep = torch.ones(3, 30, dtype=torch.bool) if mask is None else mask[:, perm]
                torch.testing.assert_close(other[keep], out[:, perm][keep], atol=1e-6, rtol=0)

    @pytest.mark.parametrize("task", ["classify", "segment"])
    def test_padded_batch_equals_alone(self, task):
        m = tiny(task)
        x, mask, clouds = padded([25, 9, 40], 40, fill=-3.0)
        out = m(x, mask)
        for i, c in enumerate(clouds):
            alone = m(c[None])
            got = out[i] if task == "classify" else out[i, : len(c)]
            torch.testing.assert_close(got, alone[0], atol=1e-5, rtol=0)

    def test_padding_values_never_matter_in_training(self):
        m = tiny("segment", dropout=0.0).train()
        x, mask, _ = padded([25, 13], 30)
        y = x.clone()
        y[~mask] = 1e3
        state = {k: v.clone() for k, v in m.state_dict().items()}
        a = m(x, mask)
        after = {k: v.clone() for k, v in m.state_dict().items()}
        m.load_state_dict(state)
        b = m(y, mask)
        assert torch.equal(a[mask], b[mask])
        assert all(torch.equal(v, after[k]) for k, v in m.state_dict().items())

    def test_errors(self):
        m = tiny()
        with pytest.raises(InputError, match=r"k=4.*cloud 0 has 3.*sample more points"):
            m(cloud(1, 3))
        x = cloud()
        x[0, 2, 0] = float("nan")
        with pytest.raises(InputError, match=r"point 2 of cloud 0.*isfinite"):
            m(x)
        with pytest.raises(InputError, match=r"x.transpose\(1, 2\)"):
            m(torch.rand(2, 3, 40))
        with pytest.raises(InputError, match="task='segment'"):
            DGCNN(3, num_categories=2)
        with pytest.raises(InputError, match="widths"):
            DGCNN(3, widths=())
        with pytest.raises(InputError, match="parameters"):
            DGCNN(3, widths=[8192] * 8, embedding=8192)

    def test_gradients_seed_and_config(self):
        m = tiny("segment", num_categories=2).train()
        x, mask, _ = padded([30, 20, 25], 30)
        logits = m(x, mask, torch.tensor([0, 1, 1]))
        target = torch.zeros(3, 30, dtype=torch.long)
        torch.nn.functional.cross_entropy(logits[mask], target[mask]).backward()
        grads = [p.grad for p in m.parameters()]
        assert all(g is not None and torch.isfinite(g).all() for g in grads)
        other = tiny("segment", num_categories=2)
        assert all(
            torch.equal(a, b)
            for a, b in zip(
                other.state_dict().values(),
                tiny("segment", num_categories=2).state_dict().values(),
                strict=True,
            )
        )
        rebuilt = type(m)(**json.loads(json.dumps(m.config)))
        assert rebuilt.config == m.config
        count = sum(p.numel() for p in m.parameters())
        assert sum(p.numel() for p in rebuilt.parameters()) == count
        rebuilt.load_state_dict(m.state_dict())
        assert (m.task, m.num_outputs, m.in_channels) == ("segment", 4, 3)


@pytest.mark.realdata
def test_bunny_knn_matches_ckdtree():
    """The PCL bunny (397 points, metres): float32 k-NN against cKDTree; real scans can
    hold equal distances, so the distances are compared (to float32 rounding)."""
    from robopercept.pointcloud import read_point_cloud

    pts = read_point_cloud(data_path("pointcloud", "pcl", "bun0.pcd")).points
    x = torch.from_numpy(pts).float()
    idx = knn_graph(x, 20).numpy()
    p32 = x.double().numpy()
    dist, want = cKDTree(p32).query(p32, 20)
    got = np.linalg.norm(p32[idx] - p32[:, None, :], axis=-1)
    np.testing.assert_allclose(got, dist, atol=1e-7)
    assert (idx == want).mean() > 0.99
    m = tiny().eval()
    perm = torch.randperm(len(x), generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(m(x[perm][None]), m(x[None]), atol=1e-6, rtol=0)
