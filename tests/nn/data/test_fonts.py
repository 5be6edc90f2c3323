"""Tests of robopercept.nn.data.fonts: digits rendered from TrueType fonts (matplotlib's by
default, the system's on request)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("PIL")

import robopercept.nn.data.fonts as fonts_module
from robopercept.errors import InputError
from robopercept.nn.data.fonts import DEFAULT_FONTS, default_fonts, find_fonts, render_digits


@pytest.fixture(scope="module")
def rendered() -> tuple[np.ndarray, np.ndarray]:
    """300 rendered digits, seed 0."""
    return render_digits(300, seed=0)


def test_shapes_dtypes_and_range(rendered):
    images, labels = rendered
    assert images.shape == (300, 1, 8, 8) and images.dtype == np.float32
    assert labels.shape == (300,) and labels.dtype == np.int64
    assert images.min() >= 0.0 and images.max() <= 1.0
    # block counts of a 32x32 bitmap in 4x4 blocks: multiples of 1/16, like sklearn's digits
    np.testing.assert_array_equal(images * 16, np.round(images * 16))


def test_labels_balanced_and_shuffled(rendered):
    _, labels = rendered
    np.testing.assert_array_equal(np.bincount(labels, minlength=10), np.full(10, 30))
    assert not np.array_equal(labels, np.tile(np.arange(10), 30))  # shuffled
    counts = np.bincount(render_digits(23, seed=1)[1], minlength=10)
    assert counts.max() - counts.min() <= 1  # n not a multiple of 10: off by one at most


def test_seeded_determinism():
    a = render_digits(40, seed=3)
    b = render_digits(40, seed=3)
    c = render_digits(40, seed=4)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


def test_no_blank_images_with_the_default_fonts(rendered):
    images, _ = rendered
    ink = images.reshape(len(images), -1).sum(axis=1)
    assert (ink > 0.5).all(), f"{int((ink <= 0.5).sum())} nearly blank images"


def test_default_fonts_are_matplotlibs_and_draw_ten_distinct_digits():
    """Every default face is a file of the installed matplotlib, and its ten digit glyphs
    are ten different, inked shapes (no box-for-everything or symbol font slipped in)."""
    import matplotlib
    from PIL import Image, ImageDraw, ImageFont

    paths = default_fonts()
    assert [p.name for p in paths] == list(DEFAULT_FONTS) and len(paths) == 22
    assert all(p.parent == Path(matplotlib.get_data_path()) / "fonts" / "ttf" for p in paths)
    for path in paths:
        font = ImageFont.truetype(str(path), 48, layout_engine=ImageFont.Layout.BASIC)
        glyphs = []
        for digit in "0123456789":
            canvas = Image.new("L", (96, 96), 0)
            ImageDraw.Draw(canvas).text((48, 48), digit, fill=255, font=font, anchor="mm")
            glyphs.append((np.asarray(canvas) > 127).tobytes())
        assert len(set(glyphs)) == 10, path.name
        assert all(any(g) for g in glyphs), path.name


def _fake_system(tmp_path: Path, monkeypatch, extra: list[Path]) -> Path:
    """Point the system font search and the home folder at a folder of ``tmp_path``
    holding only ``extra`` (copied)."""
    root = tmp_path / f"fonts{len(extra)}"
    (root / "home" / ".fonts").mkdir(parents=True)
    for i, f in enumerate(extra):
        shutil.copy(f, root / "home" / ".fonts" / f"extra{i}-{f.name}")
    monkeypatch.setattr(fonts_module, "SYSTEM_FONT_DIRS", (str(root / "share"), "~/.fonts"))
    monkeypatch.setenv("HOME", str(root / "home"))
    return root


def test_default_output_does_not_depend_on_the_systems_fonts(tmp_path, monkeypatch):
    """The issue-44 regression: the default digits are the same arrays whether the
    system's font folders are empty or hold extra fonts; the explicit system option does
    see the change (so the patched search is the one in use)."""
    reference = render_digits(200, seed=5)
    extra = default_fonts()[12:16] + default_fonts()[16:18]  # STIX and Computer Modern
    outputs, system = [], []
    for faces in ([], extra[:1], extra):
        _fake_system(tmp_path, monkeypatch, faces)
        assert len(find_fonts()) == len(faces)
        outputs.append(render_digits(200, seed=5))
        if faces:
            system.append(render_digits(200, seed=5, fonts="system")[0])
        else:
            with pytest.raises(InputError, match="fonts='default'"):
                render_digits(10, fonts="system")
    for images, labels in outputs:
        np.testing.assert_array_equal(images, reference[0])
        np.testing.assert_array_equal(labels, reference[1])
    assert not np.array_equal(system[0], system[1])
    assert not np.array_equal(system[1], reference[0])


def test_explicit_font_list(tmp_path):
    one = default_fonts()[:1]
    images, _ = render_digits(30, seed=0, fonts=one)
    np.testing.assert_array_equal(images, render_digits(30, seed=0, fonts=[str(one[0])])[0])
    assert not np.array_equal(images, render_digits(30, seed=0)[0])
    with pytest.raises(InputError, match="font files not found"):
        render_digits(5, fonts=[tmp_path / "nope.ttf"])
    with pytest.raises(InputError, match="empty list"):
        render_digits(5, fonts=[])
    for bad_fonts in ("arial", 3, [None]):
        with pytest.raises(InputError, match="'default', 'system' or a list"):
            render_digits(5, fonts=bad_fonts)  # type: ignore[arg-type]
    bad = tmp_path / "bad.ttf"
    bad.write_bytes(b"not a font")
    with pytest.raises(InputError, match="cannot read the font"):
        render_digits(5, fonts=[bad])


def test_find_fonts_skips_symbol_fonts(tmp_path):
    for name in ("A.ttf", "b.OTF", "DejaVuMathTeXGyre.ttf", "Symbol.ttf", "c.txt"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        (tmp_path / "sub" / name).write_bytes(b"")
    assert [p.name for p in find_fonts([tmp_path])] == ["A.ttf", "b.OTF"]
    assert find_fonts([tmp_path / "missing"]) == []
    assert find_fonts(str(tmp_path)) == find_fonts([tmp_path])  # one folder
    with pytest.raises(InputError, match="list of folder paths"):
        find_fonts(5)  # type: ignore[arg-type]


def test_rendered_digits_look_like_the_real_ones():
    """A classifier trained only on rendered digits recognises real (UCI) digits far
    above chance (10%): the property the sim-to-real pretraining needs."""
    pytest.importorskip("sklearn")
    from sklearn.datasets import load_digits
    from sklearn.svm import SVC

    images, labels = render_digits(2000, seed=0)
    real = load_digits()
    clf = SVC(gamma="scale").fit(images.reshape(len(images), -1), labels)
    accuracy = (clf.predict(real.data / 16.0) == real.target).mean()
    assert accuracy >= 0.45, accuracy


def test_bad_n():
    with pytest.raises(InputError, match="n must be >= 1"):
        render_digits(0)
    with pytest.raises(InputError, match="render in chunks"):
        render_digits(10**9)
    with pytest.raises(InputError, match="n must be an integer"):
        render_digits(2.5)  # type: ignore[arg-type]


def test_bad_seed_and_noise():
    with pytest.raises(InputError, match="seed must be >= 0"):
        render_digits(5, seed=-1)
    with pytest.raises(InputError, match="noise"):
        render_digits(5, noise=1.5)
