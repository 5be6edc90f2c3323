"""Tests of robopercept.nn.data.datasets: datasets, loaders, splits, statistics."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.imaging.io import write_image  # noqa: E402
from robopercept.nn.data.augment import (  # noqa: E402
    ColorJitter,
    Compose,
    GaussianNoise,
    Normalize,
    RandomAffine,
    RandomCrop,
    RandomFlip,
)
from robopercept.nn.data.datasets import (  # noqa: E402
    ArrayDataset,
    ImageFolder,
    load_digits,
    load_lfw_subset,
    normalization_stats,
    shapes_dataset,
    stratified_split,
)

# --------------------------------------------------------------------------- ArrayDataset


class TestArrayDataset:
    def test_getitem_and_dataloader(self):
        rng = np.random.default_rng(0)
        images = rng.random((10, 3, 5, 6), dtype=np.float32)
        ds = ArrayDataset(images, np.arange(10) % 2, ["a", "b"])
        x, y = ds[3]
        assert x.shape == (3, 5, 6) and x.dtype == torch.float32 and y == 1
        np.testing.assert_array_equal(x.numpy(), images[3])
        assert ds.image_shape == (3, 5, 6)
        loader = torch.utils.data.DataLoader(ds, batch_size=4, shuffle=False)
        xb, yb = next(iter(loader))
        assert xb.shape == (4, 3, 5, 6)
        assert yb.tolist() == [0, 1, 0, 1]

    def test_gray_gets_channel_and_transform_applies(self):
        ds = ArrayDataset(np.ones((2, 4, 4)), [0, 0], ["x"], transform=lambda t: 2 * t)
        x, _ = ds[0]
        assert x.shape == (1, 4, 4) and float(x.max()) == 2.0
        assert ds.images.dtype == np.float32

    def test_subset(self):
        ds = ArrayDataset(np.arange(5, dtype=np.float32)[:, None, None], [0, 1, 2, 0, 1], "abc")
        sub = ds.subset([4, 0])
        assert len(sub) == 2 and sub.labels.tolist() == [1, 0] and sub.classes == ds.classes
        assert sub.images[:, 0, 0, 0].tolist() == [4.0, 0.0]

    def test_bad_inputs(self):
        good = np.zeros((4, 1, 8, 8), np.float32)
        with pytest.raises(InputError, match="channels-last"):
            ArrayDataset(np.zeros((4, 8, 8, 3), np.float32), [0] * 4, ["a"])
        with pytest.raises(InputError, match="/ 255"):
            ArrayDataset(np.zeros((4, 8, 8), np.uint8), [0] * 4, ["a"])
        with pytest.raises(InputError, match="empty"):
            ArrayDataset(np.zeros((0, 1, 8, 8), np.float32), [], ["a"])
        with pytest.raises(InputError, match=r"0 \.\. 1"):
            ArrayDataset(good, [0, 1, 2, 0], ["a", "b"])
        with pytest.raises(InputError, match="one per image"):
            ArrayDataset(good, [0, 1], ["a", "b"])
        with pytest.raises(InputError, match="NaN"):
            ArrayDataset(np.full((4, 1, 8, 8), np.nan, np.float32), [0] * 4, ["a"])
        with pytest.raises(InputError, match="integers"):
            ArrayDataset(good, ["a", "b", "a", "b"], ["a", "b"])


# --------------------------------------------------------------------------- loaders


def test_load_digits_matches_sklearn():
    sk = pytest.importorskip("sklearn.datasets")
    ds = load_digits()
    assert ds.images.shape == (1797, 1, 8, 8) and ds.images.dtype == np.float32
    assert ds.classes == tuple(str(d) for d in range(10))
    assert ds.images.min() == 0.0 and ds.images.max() == 1.0
    ref = sk.load_digits()
    # exact: values are k / 16 for integers k, representable in float32
    np.testing.assert_array_equal(ds.images[:, 0] * 16, ref.images)
    np.testing.assert_array_equal(ds.labels, ref.target)
    assert set(np.bincount(ds.labels)) <= set(range(174, 184))  # 174..183 per class


def test_load_lfw_subset_order_and_labels():
    skd = pytest.importorskip("skimage.data")
    ds = load_lfw_subset()
    assert ds.images.shape == (200, 1, 25, 25)
    assert ds.classes == ("non-face", "face")
    # scikit-image documents: the first 100 are faces, the next 100 non-faces
    assert ds.labels[:100].tolist() == [1] * 100 and ds.labels[100:].tolist() == [0] * 100
    assert 0.0 <= ds.images.min() and ds.images.max() <= 1.0
    np.testing.assert_allclose(ds.images[:, 0] * 255, skd.lfw_subset(), atol=1e-4)


class TestImageFolder:
    @staticmethod
    def _tree(root, sizes=((6, 5), (6, 5), (6, 5))):
        rng = np.random.default_rng(1)
        written = {}
        for cls, (h, w) in zip(["dog", "cat", "cat"], sizes, strict=True):
            (root / cls).mkdir(exist_ok=True)
            img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
            name = f"{len(written)}.png"
            write_image(root / cls / name, img)
            written[(cls, name)] = img
        return written

    def test_classes_labels_pixels(self, tmp_path):
        written = self._tree(tmp_path)
        (tmp_path / "cat" / ".DS_Store").write_bytes(b"junk")  # hidden files are ignored
        ds = ImageFolder(tmp_path)
        assert ds.classes == ("cat", "dog")  # sorted by name
        assert len(ds) == 3 and ds.labels.tolist() == [0, 0, 1]
        assert ds.images.shape == (3, 3, 6, 5)
        for i, p in enumerate(ds.paths):
            ref = written[(p.parent.name, p.name)].transpose(2, 0, 1) / 255.0
            np.testing.assert_allclose(ds.images[i], ref, atol=1e-6)
        gray = ImageFolder(tmp_path, mode="gray")
        assert gray.images.shape == (3, 1, 6, 5)

    def test_non_image_file_raises_or_is_skipped(self, tmp_path):
        self._tree(tmp_path)
        bad = tmp_path / "dog" / "notes.txt"
        bad.write_text("not a picture")
        with pytest.raises(FileFormatError, match=r"notes\.txt.*skip_invalid=True"):
            ImageFolder(tmp_path)
        with pytest.warns(UserWarning, match="skipped 1 "):
            ds = ImageFolder(tmp_path, skip_invalid=True)
        assert len(ds) == 3 and ds.skipped == (bad,)

    def test_corrupt_image_raises_naming_file(self, tmp_path):
        self._tree(tmp_path)
        (tmp_path / "cat" / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\nnope")
        with pytest.raises(FileFormatError, match=r"broken\.png"):
            ImageFolder(tmp_path)
        with pytest.warns(UserWarning, match="skipped 1 "):
            assert len(ImageFolder(tmp_path, skip_invalid=True)) == 3

    def test_empty_folders(self, tmp_path):
        with pytest.raises(InputError, match="no class subfolders"):
            ImageFolder(tmp_path)
        (tmp_path / "a").mkdir()
        with pytest.raises(InputError, match="no images"):
            ImageFolder(tmp_path)
        with pytest.raises(InputError, match="does not exist"):
            ImageFolder(tmp_path / "missing")

    def test_mixed_sizes_need_size(self, tmp_path):
        self._tree(tmp_path, sizes=((6, 5), (8, 8), (6, 5)))
        with pytest.raises(InputError, match=r"size=\(width, height\)"):
            ImageFolder(tmp_path)
        ds = ImageFolder(tmp_path, size=(4, 3))
        assert ds.images.shape == (3, 3, 3, 4)
        assert 0.0 <= ds.images.min() and ds.images.max() <= 1.0


# --------------------------------------------------------------------------- shapes


def test_shapes_dataset_seeded_balanced_and_areas():
    a = shapes_dataset(2000, 32, rng=3, noise=0.0)
    b = shapes_dataset(2000, 32, rng=3, noise=0.0)
    np.testing.assert_array_equal(a.images, b.images)
    assert not np.array_equal(a.images, shapes_dataset(2000, 32, rng=4, noise=0.0).images)
    assert a.images.shape == (2000, 1, 32, 32)
    assert np.bincount(a.labels).tolist() == [500] * 4
    assert a.classes == ("circle", "square", "triangle", "cross")
    # without noise each image is two levels, background <= 0.4 < 0.6 <= shape
    area = (a.images[:, 0] > 0.5).sum(axis=(1, 2))
    lo, hi = 32 / 6, 32 / 3
    mean_r2 = (hi**3 - lo**3) / (3 * (hi - lo))  # E[r^2] for r ~ U(lo, hi)
    # area / r^2: circle pi, square 2 (corners on the circle), equilateral triangle
    # 3 sqrt(3) / 4, cross 2 * 2 * (r/2) - (r/2)^2 = 1.75. 500 draws: E[r^2] to ~2 %,
    # pixelization ~2 %: 7 % tolerance
    expect = [np.pi, 2.0, 3 * np.sqrt(3) / 4, 1.75]
    for k in range(4):
        got = area[a.labels == k].mean() / mean_r2
        assert got == pytest.approx(expect[k], rel=0.07), a.classes[k]
    noisy = shapes_dataset(8, 16, rng=0)
    assert 0.0 <= noisy.images.min() and noisy.images.max() <= 1.0
    with pytest.raises(InputError):
        shapes_dataset(0)
    with pytest.raises(InputError):
        shapes_dataset(4, noise=-1.0)


# --------------------------------------------------------------------------- split and stats


class TestStratifiedSplit:
    def test_proportions_disjoint_cover_deterministic(self):
        labels = np.r_[np.zeros(100), np.ones(50), np.full(30, 2)].astype(int)
        parts = stratified_split(labels, (0.7, 0.15, 0.15), rng=0)
        allidx = np.concatenate(parts)
        assert np.array_equal(np.sort(allidx), np.arange(labels.size))  # disjoint + cover
        for frac, p in zip((0.7, 0.15, 0.15), parts, strict=True):
            counts = np.bincount(labels[p], minlength=3)
            # each class gets f * n_k rounded to a neighbouring integer
            assert np.all(np.abs(counts - frac * np.array([100, 50, 30])) < 1)
        again = stratified_split(labels, (0.7, 0.15, 0.15), rng=0)
        assert all(np.array_equal(x, y) for x, y in zip(parts, again, strict=True))
        other = stratified_split(labels, (0.7, 0.15, 0.15), rng=1)
        assert not np.array_equal(parts[0], other[0])

    @pytest.mark.parametrize("seed", range(20))
    def test_small_sets_leave_no_part_empty(self, seed):
        # issue 46: a folder of a few meshes per class gave an empty validation or test
        # split (rounding put every item of every class in training)
        rng = np.random.default_rng(seed)
        n = int(rng.integers(3, 12))
        labels = rng.integers(0, int(rng.integers(1, 4)), n)
        parts = stratified_split(labels, (0.8, 0.1, 0.1), rng=seed)
        assert all(len(p) >= 1 for p in parts)
        assert np.array_equal(np.sort(np.concatenate(parts)), np.arange(n))

    def test_one_item_per_class_by_hand(self):
        # two classes of one item each, 90/10: class-wise rounding gives both to
        # training; validation takes the last of them
        train, val = stratified_split([0, 1], (0.9, 0.1), rng=0)
        assert (len(train), len(val)) == (1, 1)
        with pytest.raises(InputError, match="give at least 3, one per part"):
            stratified_split([0, 1], (0.8, 0.1, 0.1))

    def test_hand_case(self):
        train, test = stratified_split([0, 0, 0, 0, 1, 1, 1, 1], (0.5, 0.5), rng=0)
        assert sorted(np.asarray([0, 0, 0, 0, 1, 1, 1, 1])[train]) == [0, 0, 1, 1]
        assert not set(train) & set(test)

    def test_bad_fractions(self):
        with pytest.raises(InputError, match="sum to 1"):
            stratified_split([0, 1], (0.5, 0.4))
        with pytest.raises(InputError, match="positive"):
            stratified_split([0, 1], (1.2, -0.2))
        with pytest.raises(InputError, match="non-empty"):
            stratified_split([], (1.0,))


def test_normalization_stats_match_numpy():
    rng = np.random.default_rng(0)
    x = (rng.random((7, 3, 4, 5)) * np.array([1, 2, 3])[None, :, None, None]).astype(np.float32)
    mean, std = normalization_stats(x)
    x64 = x.astype(np.float64)
    np.testing.assert_allclose(mean, [x64[:, c].mean() for c in range(3)], rtol=1e-12)
    np.testing.assert_allclose(std, [x64[:, c].std() for c in range(3)], rtol=1e-12)
    ds = ArrayDataset(x, np.zeros(7, int), ["a"])
    train = ds.subset([0, 1, 2])
    m2, s2 = normalization_stats(train)
    np.testing.assert_allclose(m2, x64[:3].mean(axis=(0, 2, 3)), rtol=1e-12)
    # Normalize with the train stats gives zero mean, unit std on the train images
    z = Normalize(m2, s2)(torch.from_numpy(train.images)).double()
    np.testing.assert_allclose(z.mean(dim=(0, 2, 3)).numpy(), 0.0, atol=1e-5)
    np.testing.assert_allclose(z.std(dim=(0, 2, 3), unbiased=False).numpy(), 1.0, atol=1e-5)
    gray_mean, _ = normalization_stats(x[:, 0])
    assert gray_mean.shape == (1,)
    with pytest.raises(InputError, match="channels-last"):
        normalization_stats(np.zeros((2, 8, 8, 3), np.float32))
    with pytest.raises(InputError, match="> 0"):
        Normalize([0.5], [0.0])


# issue 25: hostile scalars, containers and paths refused by name at construction
_IMGS = np.random.default_rng(0).uniform(0, 1, (6, 1, 8, 8)).astype(np.float32)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: Compose(None), r"transforms must be a list of callables"),
        (lambda: Compose(float("nan")), r"transforms must be a list"),
        (lambda: GaussianNoise(std=[1, 2]), r"std must be a real number"),
        (lambda: GaussianNoise(std="3"), r"std must be a real number"),
        (lambda: GaussianNoise(std=float("inf")), r"std must be finite"),
        (lambda: Normalize([0.5], [1 + 1j]), r"std must be real numbers"),
        (lambda: Normalize([float("nan")], [1.0]), r"mean must be finite"),
        (lambda: Normalize([0.5], [1e-40]), r"std must be >= 1e-30"),
        (lambda: Normalize([0.5], [0.25])(None), r"Normalize takes a floating-point torch"),
        (lambda: RandomFlip(p=float("nan")), r"p \(a probability\) must be finite"),
        (lambda: RandomFlip(axis=["horizontal"]), r"axis must be one of"),
        (lambda: RandomAffine(scale=(1.0, None)), r"scale must be a real number"),
        (lambda: RandomAffine(scale=(1,)), r"scale must be a pair"),
        (lambda: RandomAffine(scale=(1e-300, 1.0)), r"scale must be in \[0.001, 1000\]"),
        (lambda: RandomAffine(translate=(1e300, 0.0)), r"translate must be in \[0, 1\]"),
        (lambda: RandomAffine(degrees=float("nan")), r"degrees must be finite"),
        (lambda: ColorJitter(brightness=(1 + 1j)), r"brightness must be a real number"),
        (lambda: ColorJitter(clip="yes"), r"clip must be True or False"),
        (lambda: RandomCrop((4,)), r"size must be an int or \(height, width\)"),
        (lambda: RandomFlip(generator=2**64), r"seed \(generator\) must be in"),
        (lambda: RandomFlip()(torch.zeros(1, 4, 4, dtype=torch.uint8)), r"floating-point"),
        (lambda: GaussianNoise()(np.zeros((1, 4, 4))), r"takes a torch tensor"),
        (lambda: ArrayDataset(_IMGS, [0] * 6, None), r"classes must be a sequence"),
        (lambda: ArrayDataset(_IMGS, [0] * 6, ["a"], transform=3), r"transform must be a call"),
        (lambda: ArrayDataset(_IMGS * 1e20, [0] * 6, ["a"]), r"images has values up to"),
        (lambda: ArrayDataset([[1, 2], [3]], [0], ["a"]), r"images must be array-like"),
        (lambda: ArrayDataset(_IMGS, [[0], [1, 2]], ["a"]), r"labels must be array-like"),
        (lambda: ImageFolder(3), r"root \(the image folder\) must be a file or folder path"),
        (lambda: ImageFolder(".", size=()), r"size must be \(width, height\)"),
        (lambda: ImageFolder(".", size=(2**30, 2**30)), r"would take .* lower size"),
        (lambda: ImageFolder(".", mode=None), r"mode must be one of 'rgb', 'gray'"),
        (lambda: shapes_dataset(4, noise=1 + 1j), r"noise \(a standard deviation\) must be"),
        (lambda: shapes_dataset(4, rng=-5), r"rng must be an int seed >= 0"),
        (lambda: shapes_dataset(2**40, 16), r"would take .*lower n or size"),
        (lambda: shapes_dataset(4, 2**20), r"would take"),
        (lambda: stratified_split(np.arange(30) % 3, (0.7, [1, 2], 0.15)), r"fractions must"),
        (lambda: stratified_split(np.arange(30) % 3, ("a", "b")), r"fractions must be positive"),
        (lambda: stratified_split([0.0, 1.0, float("nan")], (0.5, 0.5)), r"labels must be finite"),
    ],
)
def test_issue25_hostile_arguments_are_refused(call, match) -> None:
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_valid_extremes_still_work() -> None:
    # the bounds themselves are accepted and give correct results
    x = torch.full((1, 4, 4), 0.5)
    assert torch.equal(RandomFlip(p=np.float32(1.0), generator=0)(x), x)
    assert torch.equal(GaussianNoise(std=0.0, generator=0)(x), x)
    assert torch.allclose(RandomAffine(scale=(1.0, 1.0), translate=(0, 0))(x), x, atol=1e-6)
    assert torch.allclose(Normalize([0.5], [1e-30])(x), torch.zeros_like(x))
    ds = shapes_dataset(np.int64(4), 8, rng=np.int64(0), noise=0)
    assert len(ds) == 4 and ds.images.min() >= 0 and np.isfinite(ds.images).all()
    parts = stratified_split(np.arange(30) % 3, np.array([0.5, 0.5]))
    assert sorted(np.concatenate(parts).tolist()) == list(range(30))
