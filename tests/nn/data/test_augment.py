"""Tests of robopercept.nn.data.augment: the seeded augmentations and Normalize."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.data.augment import (  # noqa: E402
    ColorJitter,
    Compose,
    GaussianNoise,
    Normalize,
    RandomAffine,
    RandomCrop,
    RandomFlip,
)
from robopercept.nn.data.datasets import shapes_dataset  # noqa: E402


def _rand(*shape: int) -> torch.Tensor:
    """Uniform [0, 1) tensor from a fixed seed (tests never use torch's global state)."""
    return torch.rand(shape, generator=torch.Generator().manual_seed(sum(shape)))


# --------------------------------------------------------------------------- augmentations


def _aug_menu(seed):
    return [
        RandomCrop(6, padding=2, generator=seed),
        RandomFlip(0.5, generator=seed),
        RandomAffine(15, (0.1, 0.1), (0.9, 1.1), generator=seed),
        ColorJitter(0.3, 0.3, generator=seed),
        GaussianNoise(0.1, generator=seed),
    ]


class TestAugmentations:
    def test_seeded_determinism_and_shapes(self):
        x = _rand(8, 2, 8, 8)
        for a, b, c in zip(_aug_menu(5), _aug_menu(5), _aug_menu(6), strict=True):
            torch.manual_seed(123)  # global state must not matter
            ya = [a(x), a(x[0])]
            torch.manual_seed(999)
            yb = [b(x), b(x[0])]
            assert torch.equal(ya[0], yb[0]) and torch.equal(ya[1], yb[1]), type(a).__name__
            assert not torch.equal(ya[0], c(x)), type(a).__name__
            expect = (2, 6, 6) if isinstance(a, RandomCrop) else (2, 8, 8)
            assert ya[0].shape == (8, *expect) and ya[1].shape == expect

    def test_flip(self):
        x = _rand(3, 1, 4, 5)
        assert torch.equal(RandomFlip(1.0)(x), torch.flip(x, [-1]))
        assert torch.equal(RandomFlip(1.0, axis="vertical")(x), torch.flip(x, [-2]))
        assert torch.equal(RandomFlip(0.0)(x), x)
        flipped = RandomFlip(0.5, generator=0)(_rand(400, 1, 2, 2))
        assert flipped.shape == (400, 1, 2, 2)
        with pytest.raises(InputError, match="probability"):
            RandomFlip(1.5)

    def test_crop(self):
        x = _rand(4, 3, 7, 9)
        assert torch.equal(RandomCrop((7, 9), padding=0, generator=1)(x), x)
        y = RandomCrop(7, padding=1, generator=2)(x[:, :, :7, :7])
        padded = torch.nn.functional.pad(x[:, :, :7, :7], (1, 1, 1, 1))
        for k in range(4):  # every output is a 7x7 window of its padded input
            assert any(
                torch.equal(y[k], padded[k, :, i : i + 7, j : j + 7])
                for i in range(3)
                for j in range(3)
            )
        with pytest.raises(InputError, match="more padding"):
            RandomCrop(10)(x)

    def test_affine_identity_and_rotation(self):
        x = _rand(2, 1, 9, 9)
        # identity map through grid_sample (align_corners=False) samples pixel centres
        torch.testing.assert_close(RandomAffine()(x), x, atol=1e-5, rtol=0)
        # +90 degrees turns the picture counter-clockwise, as torch.rot90(x, 1, [-2, -1])
        torch.testing.assert_close(
            RandomAffine(degrees=(90, 90))(x), torch.rot90(x, 1, [-2, -1]), atol=1e-5, rtol=0
        )
        # scale 2 about the centre: the centre pixel of an odd image stays put
        y = RandomAffine(scale=(2.0, 2.0))(x)
        torch.testing.assert_close(y[:, :, 4, 4], x[:, :, 4, 4], atol=1e-5, rtol=0)
        with pytest.raises(InputError):
            RandomAffine(scale=(0.0, 1.0))

    def test_affine_translation_is_a_shift(self):
        # on a horizontal ramp I(x, y) = x, bilinear sampling is exact, so a translation by
        # t pixels gives I - t in the interior: one constant per image, |t| <= 0.2 W = 2
        ramp = torch.arange(10.0).expand(3, 1, 6, 10).clone()
        y = RandomAffine(translate=(0.2, 0.0), generator=0)(ramp)
        shifts = []
        for k in range(3):
            d = (ramp[k] - y[k])[:, :, 3:7]
            torch.testing.assert_close(d, d[0, 0, 0].expand_as(d), atol=1e-4, rtol=0)
            shifts.append(float(d[0, 0, 0]))
        assert all(abs(t) <= 2 + 1e-4 for t in shifts) and len(set(shifts)) == 3

    def test_color_jitter(self):
        x = _rand(5, 3, 4, 4) * 0.5
        torch.testing.assert_close(ColorJitter(0, 0)(x), x)
        y = ColorJitter(brightness=0.5, generator=0)(x)
        ratio = y / x  # brightness only: one factor b in [0.5, 1.5] per image
        for k in range(5):
            b = ratio[k].flatten()
            assert 0.5 <= float(b[0]) <= 1.5
            torch.testing.assert_close(b, b[0].expand_as(b), atol=1e-5, rtol=1e-5)
        # contrast keeps the mean and scales deviations by c in [0.8, 1.2]; x in
        # [0.25, 0.75] stays inside [0, 1] so nothing is clipped
        x = x + 0.25
        z = ColorJitter(contrast=0.2, generator=0)(x)
        m = x.mean(dim=(1, 2, 3), keepdim=True)
        torch.testing.assert_close(z.mean(dim=(1, 2, 3), keepdim=True), m, atol=1e-6, rtol=0)
        for k in range(5):
            far = (x[k] - m[k]).abs() > 0.05  # away from the mean: the ratio is well posed
            c = (z[k] - m[k])[far] / (x[k] - m[k])[far]
            torch.testing.assert_close(c, c[:1].expand_as(c), atol=1e-4, rtol=1e-4)
            assert 0.8 <= float(c[0]) <= 1.2
        with pytest.raises(InputError, match=r"\[0, 1\]"):
            ColorJitter(brightness=2.0)

    def test_gaussian_noise_statistics(self):
        x = torch.zeros(4, 1, 64, 64)
        y = GaussianNoise(0.2, generator=0)(x)
        assert float(y.std()) == pytest.approx(0.2, rel=0.03)  # 16k samples: SE ~0.6 %
        assert abs(float(y.mean())) < 0.01
        assert torch.equal(GaussianNoise(0.0)(x), x)

    def test_compose_order_and_bad_input(self):
        x = _rand(1, 3, 3)
        c = Compose([lambda t: t + 1, lambda t: t * 2])
        torch.testing.assert_close(c(x), (x + 1) * 2)
        assert "RandomFlip" in repr(Compose([RandomFlip(1.0)]))
        with pytest.raises(InputError, match="callables"):
            Compose([1])
        with pytest.raises(InputError, match="from_numpy"):
            RandomFlip(1.0)(np.zeros((1, 3, 3)))
        with pytest.raises(InputError, match=r"\(C, H, W\)"):
            RandomFlip(1.0)(torch.zeros(3, 3))
        with pytest.raises(InputError, match="generator"):
            RandomFlip(1.0, generator="seed")

    def test_dataset_with_augmentation_in_dataloader(self):
        ds = shapes_dataset(16, 12, rng=0)
        ds.transform = Compose([RandomCrop(12, 2, generator=0), RandomFlip(generator=0)])
        xb, yb = next(iter(torch.utils.data.DataLoader(ds, batch_size=16)))
        assert xb.shape == (16, 1, 12, 12) and yb.shape == (16,)


def test_normalize_layer() -> None:
    n = Normalize([1.0, 2.0], [2.0, 4.0])
    x = torch.ones(1, 2, 2, 2)
    np.testing.assert_allclose(n(x)[0, :, 0, 0].numpy(), [0.0, -0.25])
    assert set(n.state_dict()) == {"mean", "std"}
    with pytest.raises(InputError):
        Normalize([0.0], [0.0])  # std 0
