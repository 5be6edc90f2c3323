"""Issue 48: ``PointCloud(points, colors=uint8)`` stored 200.0 and wrote a white PLY.
uint8 colours are divided by 255, float colours outside [0, 1] are refused with the fix,
and the 8-bit colours written to PLY (and PCD) come back exactly, through our reader and
Open3D's."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.pointcloud import PointCloud, read_point_cloud, write_point_cloud
from tests.conftest import data_path

o3d = pytest.importorskip("open3d")
plyfile = pytest.importorskip("plyfile")


def _rgb8(n=50, seed=0):
    rgb = np.random.default_rng(seed).integers(0, 256, (n, 3), dtype=np.uint8)
    rgb[0] = (200, 100, 0)  # the colour
    rgb[1] = (255, 255, 255)
    rgb[2] = (0, 0, 0)
    return rgb


def _points(n=50, seed=1):
    return np.random.default_rng(seed).uniform(-1, 1, (n, 3))


def test_uint8_colours_are_divided_by_255():
    cloud = PointCloud(np.zeros((2, 3)), colors=np.array([[200, 100, 0], [255, 0, 255]], np.uint8))
    np.testing.assert_array_equal(cloud.colors, [[200 / 255, 100 / 255, 0], [1, 0, 1]])
    assert cloud.colors.dtype == np.float64
    # with_colors, select and re-construction keep the [0, 1] values (no double division)
    again = PointCloud(np.zeros((2, 3))).with_colors(np.array([[200, 100, 0]] * 2, np.uint8))
    assert again.colors[0, 0] == pytest.approx(200 / 255)
    assert cloud.select([1]).colors.tolist() == [[1.0, 0.0, 1.0]]
    assert PointCloud(cloud.points, cloud.colors).colors[0, 0] == pytest.approx(200 / 255)
    # floats in [0, 1] (and bools, and integers 0/1) are kept as they are
    np.testing.assert_array_equal(
        PointCloud(np.zeros((1, 3)), [[0.25, 1, 0]]).colors, [[0.25, 1, 0]]
    )
    np.testing.assert_array_equal(
        PointCloud(np.zeros((1, 3)), [[True, False, True]]).colors, [[1, 0, 1]]
    )


@pytest.mark.parametrize(
    "colors, words",
    [
        (np.array([[200.0, 100.0, 0.0]]), r"8-bit values: pass colors\.astype\(np\.uint8\)"),
        ([[255, 0, 0]], r"got values up to 255, 8-bit values.*colors / 255\.0"),
        (np.array([[300, 0, 0]], np.int64), r"from 0 to 300: scale them into \[0, 1\]"),
        (np.array([[40000, 0, 0]], np.uint16), r"colors / 65535\.0"),
        (np.array([[-0.1, 0.5, 0.5]]), r"from -0\.1 to 0\.5"),
        (np.array([[1.5, 0.5, 0.5]]), r"from 0\.5 to 1\.5"),
        (np.array([[np.nan, 0.5, 0.5]]), r"finite RGB in \[0, 1\]; got NaN"),
        (np.array([[np.inf, 0.5, 0.5]]), r"scale them into \[0, 1\]"),
    ],
)
def test_colours_outside_the_unit_range_are_refused_with_the_fix(colors, words):
    with pytest.raises(InputError, match=words):
        PointCloud(np.zeros((1, 3)), colors=colors)
    with pytest.raises(InputError, match=words):
        PointCloud(np.zeros((1, 3))).with_colors(colors)


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("ext", [".ply", ".pcd"])
def test_uint8_colours_round_trip_exactly_and_open3d_reads_them(tmp_path, ext, binary):
    rgb = _rgb8()
    cloud = PointCloud(_points(), colors=rgb)
    out = write_point_cloud(tmp_path / f"c{ext}", cloud, binary=binary)
    back = read_point_cloud(out)
    np.testing.assert_array_equal(back.colors, cloud.colors)  # v / 255 both ways: exact
    np.testing.assert_array_equal(np.rint(back.colors * 255).astype(np.uint8), rgb)
    ref = o3d.io.read_point_cloud(str(out))
    # Open3D reads 8-bit colours as v / 255 too: equal to float64 rounding
    np.testing.assert_allclose(np.asarray(ref.colors), cloud.colors, rtol=0, atol=1e-12)
    if ext == ".ply":  # the file itself holds the uchar values given (not 255 = white)
        v = plyfile.PlyData.read(str(out))["vertex"].data
        assert v.dtype["red"] == np.uint8
        np.testing.assert_array_equal(np.column_stack([v["red"], v["green"], v["blue"]]), rgb)


@pytest.mark.realdata
def test_real_colours_round_trip_through_ply_and_open3d(tmp_path):
    """PCL's table scene (packed rgba in PCD) written as PLY: the 8-bit colours survive,
    and Open3D reading our PLY sees what Open3D reading the original PCD sees."""
    path = data_path("pointcloud", "pcl", "table_scene_mug_stereo_textured.pcd")
    cloud = read_point_cloud(path).finite()
    out = write_point_cloud(tmp_path / "table.ply", cloud)
    back = read_point_cloud(out)
    np.testing.assert_array_equal(back.colors, cloud.colors)
    ref_pcd = o3d.io.read_point_cloud(str(path), remove_nan_points=True)
    ref_ply = o3d.io.read_point_cloud(str(out))
    np.testing.assert_allclose(np.asarray(ref_ply.colors), np.asarray(ref_pcd.colors), atol=1e-12)
    np.testing.assert_allclose(np.asarray(ref_ply.colors), cloud.colors, atol=1e-12)
    assert 0.05 < cloud.colors.mean() < 0.95  # a real picture, not white


def _ply(tmp_path, kind, rows):
    body = "\n".join(" ".join(str(v) for v in r) for r in rows)
    props = "".join(f"property {kind} {c}\n" for c in ("red", "green", "blue"))
    text = (
        f"ply\nformat ascii 1.0\nelement vertex {len(rows)}\nproperty float x\n"
        f"property float y\nproperty float z\n{props}end_header\n{body}\n"
    )
    path = tmp_path / "c.ply"
    path.write_text(text)
    return path


def test_ply_colour_properties_of_other_types(tmp_path):
    # float colours in [0, 1] are kept; float colours in (1, 255] are 8-bit values,
    # divided by 255 as Open3D does with every colour property
    unit = read_point_cloud(_ply(tmp_path, "float", [[0, 0, 0, 0.5, 1, 0]]))
    np.testing.assert_allclose(unit.colors, [[0.5, 1, 0]])
    eight = read_point_cloud(_ply(tmp_path, "float", [[0, 0, 0, 200, 10, 0]]))
    np.testing.assert_allclose(eight.colors, [[200 / 255, 10 / 255, 0]])
    ref = o3d.io.read_point_cloud(str(tmp_path / "c.ply"))
    np.testing.assert_allclose(np.asarray(ref.colors), eight.colors)
    short = read_point_cloud(_ply(tmp_path, "ushort", [[0, 0, 0, 255, 7, 0]]))
    np.testing.assert_allclose(short.colors, [[1, 7 / 255, 0]])


@pytest.mark.parametrize(
    "kind, rows, words",
    [
        ("float", [[0, 0, 0, 300, 0, 0]], "colour values run from 0 to 300"),
        ("float", [[0, 0, 0, -1, 0, 0]], "colour values run from -1 to 0"),
        ("float", [[0, 0, 0, "nan", 0, 0]], "colour values run from nan"),
        ("ushort", [[0, 0, 0, 65535, 0, 0]], "colour values run from 0 to 65535"),
        ("short", [[0, 0, 0, -5, 0, 0]], "PLY colours must be 0..255"),
    ],
)
def test_ply_colours_out_of_range_are_file_format_errors(tmp_path, kind, rows, words):
    with pytest.raises(FileFormatError, match=words):
        read_point_cloud(_ply(tmp_path, kind, rows))
