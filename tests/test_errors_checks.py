"""Typed errors and the shared input guards."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from robopercept import _checks as c
from robopercept.errors import DegenerateError, FileFormatError, InputError, RoboperceptError


def test_error_hierarchy():
    assert issubclass(InputError, ValueError) and issubclass(InputError, RoboperceptError)
    assert issubclass(FileFormatError, OSError) and issubclass(DegenerateError, RoboperceptError)


def test_guards_pass_good_values():
    img = np.zeros((4, 5, 3), np.uint8)
    assert c.check_image(img) is img
    assert c.check_shape(np.zeros((7, 3)), "pts", (None, 3)).shape == (7, 3)
    assert c.check_range(0.5, "p", 0, 1) == 0.5
    assert c.check_odd_size(5, "k") == 5
    assert c.as_float(img).dtype == np.float32
    assert c.as_float(img.astype(np.float64)).dtype == np.float64


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (
            lambda: c.check_image(np.zeros((3, 480, 640))),
            r"channels-first\? use image.transpose\(1, 2, 0\)",
        ),
        (lambda: c.check_image(np.zeros((8, 8, 4))), r"RGBA\? drop alpha"),
        (lambda: c.check_image(np.zeros((8, 8, 1))), r"image\[\.\.\., 0\]"),
        (lambda: c.check_image(np.zeros(8)), "got 1-D"),
        (lambda: c.check_image(np.zeros((8, 8, 3)), allow_color=False), "rgb_to_gray"),
        (lambda: c.check_image(np.zeros((8, 8), bool)), "astype"),
        (lambda: c.check_image(np.zeros((8, 8), np.complex64)), "dtype"),
        (lambda: c.check_image([[1, 2], [3]]), "rectangular|inhomogeneous|array"),
        (lambda: c.check_finite(np.array([1.0, np.inf]), "x"), "1 NaN/inf"),
        (lambda: c.check_nonempty(np.zeros((0, 3)), "pts"), "empty"),
        (lambda: c.check_shape(np.zeros((3, 2)), "pts", (None, 3)), r"\(N, 3\)"),
        (lambda: c.check_ndim(np.zeros(3), "x", (2,)), "2-D"),
        (lambda: c.check_range(2.0, "p", 0, 1), r"\[0, 1\]"),
        (lambda: c.check_range("a", "p", 0, 1), "number"),
        (lambda: c.check_positive(0, "s"), r"\(0, inf\]"),
        (lambda: c.check_odd_size(4, "k"), "try 5"),
        (lambda: c.check_odd_size(3.0, "k"), "odd integer"),
        (lambda: c.check_choice("x", "mode", ("a", "b")), "one of 'a', 'b'"),
        (lambda: c.check_kernel(np.ones((2, 2), dtype="U1"), "k"), "numeric"),
    ],
)
def test_guard_messages_say_expected_got_fix(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_import_is_light():
    code = (
        "import sys, time; t = time.perf_counter(); import robopercept, robopercept.imaging, "
        "robopercept.viz, robopercept.cli.main; dt = time.perf_counter() - t; "
        "bad = [m for m in ('torch', 'cv2', 'open3d', 'sklearn', 'skimage') if m in sys.modules]; "
        "print(dt, bad)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    _dt, bad = out.stdout.split(maxsplit=1)
    assert bad.strip() == "[]", f"import pulled in heavy modules: {bad}"
    code2 = (
        "import sys, robopercept; print(sorted(m for m in sys.modules if m.startswith('numba')))"
    )
    out2 = subprocess.run([sys.executable, "-c", code2], capture_output=True, text=True, check=True)
    assert out2.stdout.strip() == "[]"  # the bare package imports no JIT at all


# issue 25: paths of every reader and writer go through as_path (bytes, None, an int,
# a NUL byte or a 300-character name gave TypeError, ValueError or OSError)
@pytest.mark.parametrize(
    ("value", "words"),
    [
        (None, "must be a file or folder path"),
        (3, "must be a file or folder path"),
        (["a.png"], "must be a file or folder path"),
        ("", "must not be empty"),
        ("a\x00b.png", "NUL byte"),
        ("n" * 300 + ".png", "file name too long"),
        ("d/" * 2100 + "x.png", "file name too long"),
    ],
)
def test_as_path_refuses_what_cannot_name_a_file(value, words):
    from robopercept._checks import as_path

    with pytest.raises(InputError, match=words):
        as_path(value, "path")


def test_as_path_takes_str_bytes_and_pathlike(tmp_path):
    from pathlib import Path

    from robopercept._checks import as_path, check_file

    assert as_path(b"out/plane.csv") == Path("out/plane.csv")
    assert as_path(tmp_path) == tmp_path
    assert as_path("n" * 255) == Path("n" * 255)  # the longest name Linux allows
    with pytest.raises(InputError, match="the path of an image file"):
        check_file(None, "an image file")


def test_plain_repr_is_bounded_for_hostile_values():
    # a list nested far past the recursion limit, a huge array, a long string: a short
    # message, never RecursionError (issue 47: check_int(stride=<deep list>) raised it)
    deep: list = []
    for _ in range(10_000):
        deep = [deep]
    assert c.plain_repr(deep) == "[[[[[[[...]]]]]]]"
    with pytest.raises(InputError, match=r"stride must be an integer; got \[\[\["):
        c.check_int(deep, "stride")
    assert c.plain_repr(np.arange(1000)).endswith("29, ...]")
    assert len(c.plain_repr("x" * 10**6)) < 300
    assert c.plain_repr((np.float64(1.5), 2)) == "(1.5, 2)"

    class Broken:
        def __repr__(self):
            raise RuntimeError("no")

    assert c.plain_repr(Broken()).startswith("<Broken")
