"""Tests of robopercept.nn.pose.lifting: Procrustes alignment and the MPJPE metrics and
the lifting network (fixtures in conftest.py)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from scipy.spatial import procrustes as scipy_procrustes  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.pose.lifting import (  # noqa: E402
    LiftingMLP,
    SimilarityTransform,
    mpjpe,
    pa_mpjpe,
    procrustes_align,
    train_lifter,
)
from robopercept.nn.pose.views import PELVIS, random_views  # noqa: E402

# ================================================================================ metrics


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return Rotation.random(random_state=rng).as_matrix()


class TestProcrustes:
    def test_umeyama_papers_example(self):
        # Umeyama (1991), section IV: x = (0,0), (1,0), (0,2) onto y = (0,0), (-1,0),
        # (0,2) (a mirror image): c = 0.721, R = [[0.832, 0.555], [-0.555, 0.832]],
        # t = (-0.800, 0.400), mean squared error 0.533 -- printed to 3 decimals
        x = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]]
        y = np.array([[0.0, 0.0], [-1.0, 0.0], [0.0, 2.0]])
        aligned, tr = procrustes_align(x, y, return_transform=True)
        assert tr.scale == pytest.approx(0.721, abs=5e-4)
        np.testing.assert_allclose(tr.rotation, [[0.832, 0.555], [-0.555, 0.832]], atol=5e-4)
        np.testing.assert_allclose(tr.translation, [-0.8, 0.4], atol=1e-12)
        assert ((aligned - y) ** 2).sum(1).mean() == pytest.approx(0.533, abs=5e-4)
        np.testing.assert_allclose(tr.apply(x), aligned, atol=1e-12)

    def test_similar_copy_aligns_exactly(self, rng):
        truth = rng.normal(size=(16, 3))
        r = random_rotation(rng)
        pred = 0.37 * truth @ r.T + [4.0, -2.0, 9.0]
        aligned, tr = procrustes_align(pred, truth, return_transform=True)
        np.testing.assert_allclose(aligned, truth, atol=1e-9)
        assert tr.scale == pytest.approx(1 / 0.37, rel=1e-12)
        np.testing.assert_allclose(tr.rotation, r.T, atol=1e-12)
        assert pa_mpjpe(pred, truth) < 1e-9

    def test_batch_is_per_sample(self, rng):
        truth = rng.normal(size=(5, 16, 3))
        pred = np.stack(
            [(i + 1) * t @ random_rotation(rng).T + rng.normal(size=3) for i, t in enumerate(truth)]
        )
        aligned, tr = procrustes_align(pred, truth, return_transform=True)
        np.testing.assert_allclose(aligned, truth, atol=1e-9)
        assert tr.rotation.shape == (5, 3, 3) and tr.translation.shape == (5, 3)
        np.testing.assert_allclose(tr.scale, 1 / np.arange(1, 6), rtol=1e-12)
        assert pa_mpjpe(pred, truth, per_sample=True).shape == (5,)

    def test_reflection_is_not_forgiven(self, rng):
        truth = rng.normal(size=(16, 3))
        mirror = truth * [-1.0, 1.0, 1.0]
        _, tr = procrustes_align(mirror, truth, return_transform=True)
        assert np.linalg.det(tr.rotation) == pytest.approx(1.0, abs=1e-12)
        assert pa_mpjpe(mirror, truth) > 0.1
        # scipy's procrustes allows reflections: the mirror image aligns exactly there
        _, _, disparity = scipy_procrustes(truth, mirror)
        assert disparity < 1e-20
        # the rotation is the proper one of Kabsch (scipy's align_vectors, no reflection)
        x0, y0 = mirror - mirror.mean(0), truth - truth.mean(0)
        kabsch, _ = Rotation.align_vectors(y0, x0)
        np.testing.assert_allclose(tr.rotation, kabsch.as_matrix(), atol=1e-9)

    @pytest.mark.parametrize("noise", [0.05, 0.5])
    def test_disparity_matches_scipy(self, rng, noise):
        # scipy standardizes both sets and finds the best orthogonal map: with no
        # reflection involved, its disparity is our residual over the truth's spread,
        # sum |aligned - y|^2 / sum |y - mean y|^2; float64 round-off only (1e-10)
        for _ in range(5):
            truth = rng.normal(size=(16, 3))
            pred = 2.5 * truth @ random_rotation(rng).T + 1.0 + rng.normal(0, noise, (16, 3))
            aligned = procrustes_align(pred, truth)
            ours = ((aligned - truth) ** 2).sum() / ((truth - truth.mean(0)) ** 2).sum()
            _, _, disparity = scipy_procrustes(truth, pred)
            assert ours == pytest.approx(disparity, rel=1e-10, abs=1e-14)

    def test_never_better_than_scipy_on_random_sets(self, rng):
        # unrelated sets: about half want a reflection, which ours may not use
        worse = 0
        for _ in range(40):
            truth, pred = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
            aligned = procrustes_align(pred, truth)
            ours = ((aligned - truth) ** 2).sum() / ((truth - truth.mean(0)) ** 2).sum()
            disparity = scipy_procrustes(truth, pred)[2]
            assert ours >= disparity - 1e-12
            worse += ours > disparity + 1e-9
        assert 5 < worse < 35

    def test_collapsed_prediction_goes_to_the_centroid(self):
        truth = np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]])
        aligned, tr = procrustes_align(np.ones((4, 3)), truth, return_transform=True)
        np.testing.assert_allclose(aligned, np.full((4, 3), 0.5), atol=1e-12)
        assert tr.scale == 0.0

    def test_invariance_of_pa_mpjpe(self, rng):
        truth, pred = rng.normal(size=(16, 3)), rng.normal(size=(16, 3))
        moved = 3.0 * pred @ random_rotation(rng).T - 7.0
        assert pa_mpjpe(moved, truth) == pytest.approx(pa_mpjpe(pred, truth), rel=1e-9)

    @pytest.mark.parametrize(
        ("pred", "truth", "match"),
        [
            (np.zeros((4, 3)), np.zeros((5, 3)), "same shape"),
            (np.zeros(3), np.zeros(3), r"\(J, D\) or \(N, J, D\)"),
            (np.full((4, 3), np.nan), np.zeros((4, 3)), "finite"),
            ([["a", "b"]], [[1, 2]], "real numbers"),
        ],
    )
    def test_bad_input(self, pred, truth, match):
        with pytest.raises(InputError, match=match):
            procrustes_align(pred, truth)
        with pytest.raises(InputError, match=match):
            pa_mpjpe(pred, truth)

    def test_similarity_apply_checks_shape(self):
        tr = SimilarityTransform(1.0, np.eye(3), np.zeros(3))
        with pytest.raises(InputError, match=r"points must be \(J, 3\)"):
            tr.apply(np.zeros((4, 2)))


class TestMPJPE:
    def test_hand_case(self):
        pred = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
        truth = [[0.0, 0.0, 1.0], [1.0, 3.0, 4.0]]  # errors 1 and 5
        assert mpjpe(pred, truth) == 3.0
        batch = mpjpe([pred, pred], [truth, pred], per_sample=True)
        np.testing.assert_array_equal(batch, [3.0, 0.0])
        assert mpjpe([pred, pred], [truth, pred]) == 1.5

    def test_root_relative(self):
        pred = np.array([[[1.0, 1.0, 1.0], [2.0, 1.0, 1.0]]])
        truth = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]])
        assert mpjpe(pred, truth) == pytest.approx(np.sqrt(3))
        assert mpjpe(pred, truth, root=0) == 0.0

    def test_bad_root(self):
        with pytest.raises(InputError, match=r"root must index a joint, 0\.\.1"):
            mpjpe(np.zeros((2, 3)), np.zeros((2, 3)), root=2)


# ============================================================================= the network


@pytest.fixture(scope="module")
def training_pairs(library_poses):
    v = random_views(library_poses, 8, rng=11)
    return v.keypoints2d * 100.0, v.joints3d


def small_net(seed: int = 0) -> LiftingMLP:
    return LiftingMLP(16, width=64, blocks=1, dropout=0.1, random_state=seed)


@pytest.fixture(scope="module")
def trained(training_pairs):
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        net = small_net()
        losses = train_lifter(net, *training_pairs, epochs=8, batch_size=128, lr=2e-3)
    finally:
        torch.set_num_threads(before)
    return net, losses


class TestLiftingMLP:
    def test_shapes(self):
        net = LiftingMLP(16, width=32, blocks=2)
        assert net(torch.zeros(5, 32)).shape == (5, 48)
        assert net.lift(np.random.default_rng(0).normal(size=(7, 16, 2))).shape == (7, 16, 3)
        assert net.lift(np.random.default_rng(0).normal(size=(16, 2))).shape == (16, 3)
        assert net.lift(np.zeros((0, 16, 2))).shape == (0, 16, 3)  # an empty batch
        n_linear = sum(isinstance(m, torch.nn.Linear) for m in net.modules())
        n_bn = sum(isinstance(m, torch.nn.BatchNorm1d) for m in net.modules())
        assert (n_linear, n_bn) == (1 + 2 * 2 + 1, 1 + 2 * 2)
        assert set(net.state_dict()) >= {"input_mean", "input_std", "output_mean", "output_std"}

    def test_seeded_weights_leave_torch_alone(self):
        state = torch.get_rng_state()
        a, b = small_net(3), small_net(3)
        assert torch.equal(state, torch.get_rng_state())
        for (name, x), y in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
            assert torch.equal(x, y), name
        assert not torch.equal(a.head.weight, small_net(4).head.weight)

    def test_seeded_training(self, training_pairs, torch_one_thread):
        kp, j3 = training_pairs[0][:512], training_pairs[1][:512]
        nets = [small_net(), small_net(), small_net()]
        state = torch.get_rng_state()
        la = train_lifter(nets[0], kp, j3, epochs=2, batch_size=64, noise=1.0, random_state=5)
        lb = train_lifter(nets[1], kp, j3, epochs=2, batch_size=64, noise=1.0, random_state=5)
        train_lifter(nets[2], kp, j3, epochs=2, batch_size=64, noise=1.0, random_state=6)
        assert torch.equal(state, torch.get_rng_state())
        np.testing.assert_array_equal(la, lb)
        for x, y in zip(nets[0].state_dict().values(), nets[1].state_dict().values(), strict=True):
            assert torch.equal(x, y)
        assert not torch.equal(nets[0].head.weight, nets[2].head.weight)

    def test_training_beats_the_mean_pose(self, trained, held_out, mean_pose_error):
        # measured (4800 pairs, width 64, 8 epochs): 112 mm against 185 mm for the mean
        # pose (0.60; seeds 1 and 2 give 110 mm); the loss falls from 0.72 to 0.23
        net, losses = trained
        assert losses[-1] < 0.5 * losses[0]
        px, truth = held_out
        assert pa_mpjpe(net.lift(px), truth) < 0.7 * mean_pose_error

    def test_lift_is_self_contained_and_rooted(self, trained, held_out):
        net, _ = trained
        px, _ = held_out
        out = net.lift(px[:20])
        assert np.all(out[:, PELVIS] == 0)
        fresh = LiftingMLP(16, width=64, blocks=1, dropout=0.1, random_state=99)
        fresh.load_state_dict(net.state_dict())
        np.testing.assert_array_equal(fresh.lift(px[:20]), out)
        # float32 network: moving and scaling the 2-D input changes only round-off
        np.testing.assert_allclose(net.lift(2.0 * px[:20] + 9.0), out, atol=1e-5)
        assert not net.training

    def test_bad_input(self, training_pairs):
        net = small_net()
        kp, j3 = training_pairs
        with pytest.raises(InputError, match="network's 16 joints; got 15"):
            net.lift(np.zeros((2, 15, 2)))
        with pytest.raises(InputError, match="needs every joint"):
            net.lift(np.where(np.eye(16, 2, dtype=bool), np.nan, 1.0))
        with pytest.raises(InputError, match=r"x must be a \(B, 32\) tensor"):
            net(torch.zeros(2, 30))
        with pytest.raises(InputError, match="same poses; got 10 and 9"):
            train_lifter(net, kp[:10], j3[:9])
        with pytest.raises(InputError, match="at least 2 pairs"):
            train_lifter(net, kp[:1], j3[:1])
        with pytest.raises(InputError, match="must be a LiftingMLP"):
            train_lifter(torch.nn.Linear(2, 2), kp, j3)
        with pytest.raises(InputError, match="model's 15 joints"):
            train_lifter(LiftingMLP(15, width=8), kp, j3)
        with pytest.raises(InputError, match="root must index a joint"):
            LiftingMLP(4)
        with pytest.raises(InputError, match="dropout must be in"):
            LiftingMLP(dropout=1.0)
