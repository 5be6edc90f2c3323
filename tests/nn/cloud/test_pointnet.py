"""Tests of robopercept.nn.cloud.pointnet: shapes, the T-Nets and their regularizer, masks and
padding, permutation invariance, critical points, errors, config round trips."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.cloud.pointnet import (  # noqa: E402
    CloudOutput,
    MaskedBatchNorm,
    PointNet,
    SharedMLP,
    TNet,
    check_cloud_batch,
    critical_points,
    masked_max_pool,
    transform_regularizer,
)
from tests.conftest import data_path  # noqa: E402

SMALL = {"width": 0.125}


def small(task: str = "classify", **kw) -> PointNet:
    torch.manual_seed(0)
    return randomize_norms(PointNet(kw.pop("num_outputs", 4), task=task, **{**SMALL, **kw})).eval()


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


def cloud(b: int = 2, n: int = 40, c: int = 3, seed: int = 0) -> torch.Tensor:
    return torch.rand(b, n, c, generator=torch.Generator().manual_seed(seed)) * 2 - 1


def padded(lengths: list[int], n: int, seed: int = 1, fill: float = 0.0):
    """Clouds of the given lengths padded to ``n`` with ``fill``, the mask, the clouds."""
    g = torch.Generator().manual_seed(seed)
    clouds = [torch.rand(m, 3, generator=g) for m in lengths]
    x = torch.full((len(lengths), n, 3), fill)
    mask = torch.zeros(len(lengths), n, dtype=torch.bool)
    for i, c in enumerate(clouds):
        x[i, : len(c)] = c
        mask[i, : len(c)] = True
    return x, mask, clouds


class TestShapes:
    def test_classify(self):
        m = small()
        out = m.forward_aux(cloud())
        assert isinstance(out, CloudOutput)
        assert out.logits.shape == (2, 4)
        assert out.global_feature.shape == (2, 128) == out.pooled_index.shape
        assert out.pooled_index.dtype == torch.long
        assert [t.shape for t in out.transforms] == [(2, 3, 3), (2, 8, 8)]
        assert out.graphs == []
        assert torch.equal(m(cloud()), out.logits)

    def test_segment_with_categories(self):
        m = small("segment", num_outputs=5, num_categories=3)
        out = m.forward_aux(cloud(), category=torch.tensor([0, 2]))
        assert out.logits.shape == (2, 40, 5)
        # the category changes the per-point logits, not the pooled feature
        other = m.forward_aux(cloud(), category=torch.tensor([1, 2]))
        assert torch.equal(out.global_feature, other.global_feature)
        assert not torch.allclose(out.logits[0], other.logits[0])
        assert torch.equal(out.logits[1], other.logits[1])

    def test_full_width_and_no_transforms(self):
        m = PointNet(40).eval()
        out = m.forward_aux(cloud(1, 64))
        assert out.global_feature.shape == (1, 1024)
        assert [t.shape for t in out.transforms] == [(1, 3, 3), (1, 64, 64)]
        bare = PointNet(3, input_transform=False, feature_transform=False, **SMALL).eval()
        assert bare.forward_aux(cloud()).transforms == []

    def test_extra_channels(self):
        """Normals ride along: the input T-Net transforms only xyz."""
        m = small(in_channels=6)
        assert m(cloud(2, 30, 6)).shape == (2, 4)
        assert m.forward_aux(cloud(2, 30, 6)).transforms[0].shape == (2, 3, 3)


class TestTNet:
    def test_identity_at_init(self):
        t = TNet(3, width=0.25)
        x = cloud(3, 20)
        for mode in (True, False):
            t.train(mode)
            assert torch.equal(t(x), torch.eye(3).expand(3, 3, 3))
        assert torch.equal(
            TNet(16, width=0.125).eval()(cloud(2, 10, 16)), torch.eye(16).expand(2, -1, -1)
        )

    def test_regularizer_zero_for_orthogonal(self):
        g = torch.Generator().manual_seed(3)
        q, _ = torch.linalg.qr(torch.randn(5, 7, 7, generator=g, dtype=torch.float64))
        # Q Q^T = I to rounding: the loss is a sum of 49 squares of ~1e-16
        assert float(transform_regularizer(q)) < 1e-28

    def test_regularizer_formula(self):
        a = torch.randn(4, 3, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
        want = np.mean([np.linalg.norm(np.eye(3) - m @ m.T, "fro") ** 2 for m in a.numpy()])
        assert float(transform_regularizer(a)) == pytest.approx(want, rel=1e-12)
        assert float(transform_regularizer(2 * torch.eye(2)[None])) == 18.0

    def test_regularizer_bad_input(self):
        with pytest.raises(InputError, match=r"\(B, k, k\).*A\[None\]"):
            transform_regularizer(torch.eye(3))


class TestMasks:
    def test_masked_max_pool(self):
        f = torch.tensor([[[1.0, 5.0], [3.0, 0.0], [9.0, 9.0]]])
        v, i = masked_max_pool(f, torch.tensor([[True, True, False]]))
        assert v.tolist() == [[3.0, 5.0]] and i.tolist() == [[1, 0]]
        with pytest.raises(InputError, match="mask must be a bool tensor"):
            masked_max_pool(f, torch.ones(1, 2, dtype=torch.bool))

    @pytest.mark.parametrize("task", ["classify", "segment"])
    def test_padded_batch_equals_alone(self, task):
        m = small(task)
        x, mask, clouds = padded([25, 13, 40], 40, fill=1e6)
        out = m(x, mask)
        for i, c in enumerate(clouds):
            alone = m(c[None])
            got = out[i] if task == "classify" else out[i, : len(c)]
            # same rows through the same eval-mode layers: only matmul blocking differs
            torch.testing.assert_close(got, alone[0], atol=1e-5, rtol=0)

    def test_padding_values_never_matter(self):
        """Whatever sits in the padding (even NaN), training-mode outputs and the batch
        statistics of the real points are the same."""
        m = small("segment", dropout=0.0).train()
        x, mask, _ = padded([25, 13], 30, fill=0.0)
        y = x.clone()
        y[~mask] = float("nan")
        state = {k: v.clone() for k, v in m.state_dict().items()}
        a = m(x, mask)
        stats_a = {k: v.clone() for k, v in m.state_dict().items()}
        m.load_state_dict(state)
        b = m(y, mask)
        assert torch.equal(a[mask], b[mask])
        for k, v in m.state_dict().items():
            assert torch.equal(v, stats_a[k]), k

    def test_masked_batchnorm_matches_torch_on_real_rows(self):
        torch.manual_seed(0)
        ours, ref = MaskedBatchNorm(6), torch.nn.BatchNorm1d(6)
        x = torch.randn(3, 10, 6) * 3 + 1
        mask = torch.rand(3, 10) > 0.4
        for _ in range(2):  # two steps: the running statistics too
            got = ours(x, mask)
            want = ref(x[mask])
        # same sums in another order: float32 rounding
        torch.testing.assert_close(got[mask], want, atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(ours.running_mean, ref.running_mean)
        torch.testing.assert_close(ours.running_var, ref.running_var)
        ours.eval(), ref.eval()
        torch.testing.assert_close(ours(x), ref(x.reshape(-1, 6)).reshape(3, 10, 6))

    def test_batchnorm_needs_two_values(self):
        with pytest.raises(InputError, match="more than one value per channel"):
            small().train()(cloud(1, 20))


class TestPermutation:
    @pytest.mark.parametrize("masked", [False, True])
    @pytest.mark.parametrize("task", ["classify", "segment"])
    def test_invariance(self, task, masked):
        m = small(task)
        x, mask, _ = padded([30, 17, 22], 30, seed=4)
        if not masked:
            x, mask = cloud(3, 30, seed=4), None
        out = m.forward_aux(x, mask)
        g = torch.Generator().manual_seed(7)
        for _ in range(3):
            perm = torch.randperm(30, generator=g)
            other = m.forward_aux(x[:, perm], None if mask is None else mask[:, perm])
            # max pooling is order-free; per-point rows are computed alike
            torch.testing.assert_close(other.global_feature, out.global_feature, atol=1e-6, rtol=0)
            want = out.logits if task == "classify" else out.logits[:, perm]
            if mask is not None and task == "segment":
                keep = mask[:, perm]
                torch.testing.assert_close(other.logits[keep], want[keep], atol=1e-6, rtol=0)
            else:
                torch.testing.assert_close(other.logits, want, atol=1e-6, rtol=0)
            # the argmax follows its point (channels above 0: ReLU zeros tie everywhere)
            live = out.global_feature > 0
            assert torch.equal(perm[other.pooled_index][live], out.pooled_index[live])


class TestCriticalPoints:
    @pytest.mark.parametrize("transforms", [True, False])
    def test_same_global_feature_on_critical_points(self, transforms):
        m = small(input_transform=transforms, feature_transform=transforms)
        pts = cloud(1, 300, seed=9)[0]
        idx = critical_points(m, pts)
        assert idx.dtype == np.int64 and np.all(np.diff(idx) > 0)
        assert 0 < len(idx) < 300
        full = m.forward_aux(pts[None]).global_feature
        sub = m.forward_aux(pts[idx][None]).global_feature
        # the paper's claim: u(C_S) = u(S); the maxima are the same numbers
        torch.testing.assert_close(sub, full, atol=1e-6, rtol=0)
        if transforms:  # without the T-Nets' points the transforms would change
            strict = critical_points(m, pts, include_transforms=False)
            assert set(strict) <= set(idx)

    def test_mask_and_mode(self):
        m = small().train()
        pts = cloud(1, 50, seed=2)[0].numpy()
        mask = np.arange(50) < 30
        idx = critical_points(m, pts, mask)
        assert idx.max() < 30
        assert m.training  # restored

    def test_bad_inputs(self):
        with pytest.raises(InputError, match="points as columns"):
            critical_points(small(), np.zeros((3, 50)))
        with pytest.raises(InputError, match="must be a PointNet"):
            critical_points(SharedMLP([3, 4]), np.zeros((5, 3)))


class TestErrors:
    def test_channels_first(self):
        with pytest.raises(InputError, match=r"x.transpose\(1, 2\)"):
            small()(torch.rand(2, 3, 50))

    def test_single_cloud(self):
        with pytest.raises(InputError, match=r"x.unsqueeze\(0\)"):
            small()(torch.rand(50, 3))

    def test_nan(self):
        x = cloud()
        x[1, 7, 2] = float("nan")
        with pytest.raises(InputError, match=r"point 7 of cloud 1.*isfinite"):
            small()(x)

    def test_other_bad_inputs(self):
        m = small()
        with pytest.raises(InputError, match=r"torch\.from_numpy"):
            m(np.zeros((2, 10, 3)))
        with pytest.raises(InputError, match="in_channels=4"):
            m(torch.rand(2, 10, 4))
        with pytest.raises(InputError, match=r"x.float\(\)"):
            m(torch.ones(2, 10, 3, dtype=torch.int64))
        with pytest.raises(InputError, match=r"x.to\(torch.float32\)"):
            m(torch.rand(2, 10, 3, dtype=torch.float64))
        empty = torch.ones(2, 40, dtype=torch.bool)
        empty[1] = False
        with pytest.raises(InputError, match="cloud 1 of the batch has no real point"):
            m(cloud(), empty)
        with pytest.raises(InputError, match="mask must have shape"):
            m(cloud(), torch.ones(2, 39, dtype=torch.bool))
        with pytest.raises(InputError, match="num_categories=0"):
            m(cloud(), category=torch.tensor([0, 1]))

    def test_category_errors(self):
        m = small("segment", num_categories=2)
        with pytest.raises(InputError, match="pass category"):
            m(cloud())
        with pytest.raises(InputError, match=r"in \[0, 2\)"):
            m(cloud(), category=torch.tensor([0, 2]))
        with pytest.raises(InputError, match="task='segment'"):
            PointNet(3, num_categories=4)

    def test_constructor_errors(self):
        with pytest.raises(InputError, match="width"):
            PointNet(3, width=0)
        with pytest.raises(InputError, match="task"):
            PointNet(3, task="detect")
        with pytest.raises(InputError, match="num_outputs"):
            PointNet(0)

    def test_check_cloud_batch_zeros_padding(self):
        x, mask, _ = padded([3, 5], 5, fill=7.0)
        out, m, _ = check_cloud_batch(x, 3, mask)
        assert torch.equal(out[~mask], torch.zeros(2, 3)) and m is not None
        assert check_cloud_batch(x, 3, torch.ones(2, 5, dtype=torch.bool))[1] is None


class TestTraining:
    def test_gradients_finite(self):
        m = small()
        m.train()
        x, mask, _ = padded([30, 20, 25, 12], 30)
        out = m.forward_aux(x, mask)
        loss = torch.nn.functional.cross_entropy(out.logits, torch.tensor([0, 1, 2, 3]))
        loss = loss + 1e-3 * transform_regularizer(out.transforms[1])
        loss.backward()
        grads = [p.grad for p in m.parameters()]
        assert all(g is not None and torch.isfinite(g).all() for g in grads)
        assert any(float(g.abs().sum()) > 0 for g in grads)

    def test_seeded_init_and_config(self):
        a, b = small("segment", num_categories=3), small("segment", num_categories=3)
        for (ka, va), (kb, vb) in zip(a.state_dict().items(), b.state_dict().items(), strict=True):
            assert ka == kb and torch.equal(va, vb)
        rebuilt = type(a)(**json.loads(json.dumps(a.config)))
        assert rebuilt.config == a.config
        count = sum(p.numel() for p in a.parameters())
        assert sum(p.numel() for p in rebuilt.parameters()) == count
        rebuilt.load_state_dict(a.state_dict())
        assert (a.task, a.num_outputs, a.in_channels) == ("segment", 4, 3)


@pytest.mark.realdata
def test_bunny_critical_points_and_invariance():
    """The PCL bunny (397 points): the critical set alone gives the global feature, and
    the output ignores the point order."""
    from robopercept.pointcloud import read_point_cloud

    pts = read_point_cloud(data_path("pointcloud", "pcl", "bun0.pcd")).points
    pts = (pts - pts.mean(0)) / np.abs(pts - pts.mean(0)).max()
    x = torch.from_numpy(pts).float()
    m = small(input_transform=False)
    idx = critical_points(m, x)
    assert len(idx) < len(pts) // 2
    full = m.forward_aux(x[None])
    torch.testing.assert_close(m.forward_aux(x[idx][None]).global_feature, full.global_feature)
    perm = torch.randperm(len(x), generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(m(x[perm][None]), full.logits, atol=1e-6, rtol=0)
