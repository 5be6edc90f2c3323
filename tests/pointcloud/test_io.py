"""PLY/PCD reading and writing: Open3D parity on every PCL file, round trips, bad files."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.pointcloud import PointCloud, read_pcd, read_point_cloud, write_point_cloud
from robopercept.pointcloud.io import _lzf_decompress
from tests.conftest import data_path

o3d = pytest.importorskip("open3d")

PCL_FILES = [
    ("pcl", "bun0.pcd"),
    ("pcl", "bun4.pcd"),
    ("pcl", "bunny.pcd"),
    ("pcl", "car6.pcd"),
    ("pcl", "five_people.pcd"),
    ("pcl", "lamppost.pcd"),
    ("pcl", "milk.pcd"),
    ("pcl", "milk_cartoon_all_small_clorox.pcd"),
    ("pcl", "office1.pcd"),
    ("pcl", "table_scene_mug_stereo_textured.pcd"),
    ("pcl_mOSD", "test0.pcd"),
    ("pcl_terrain", "CSite1_red2-utm.pcd"),
]


def finite_points(points):
    return points[np.isfinite(points).all(axis=1)]


@pytest.mark.realdata
@pytest.mark.parametrize(("folder", "name"), PCL_FILES)
def test_pcl_files_match_open3d_and_round_trip(tmp_path, folder, name):
    path = data_path("pointcloud", folder, name)
    ours = read_point_cloud(path)
    ref = o3d.io.read_point_cloud(str(path))
    # the same finite points in the same order, bit for bit (both widen float32)
    np.testing.assert_array_equal(finite_points(ours.points), finite_points(np.asarray(ref.points)))
    fin = ours.finite_mask()
    if ref.has_colors():
        np.testing.assert_allclose(ours.colors[fin], np.asarray(ref.colors)[fin], atol=1e-12)
    if ref.has_normals():
        np.testing.assert_allclose(ours.normals[fin], np.asarray(ref.normals)[fin], atol=1e-6)
    header = read_pcd(path)
    if header.height > 1:
        assert ours.shape == (header.height, header.width)
    # round trips through our writer, read back by us and by Open3D (ascii on the first
    # 5000 points: text I/O of 300k points would only slow the suite down)
    full = ours.finite()
    for ext in (".ply", ".pcd"):
        for binary in (True, False):
            clean = full if binary else full.select(np.arange(min(len(full), 5000)))
            out = write_point_cloud(tmp_path / f"rt{int(binary)}{ext}", clean, binary=binary)
            back = read_point_cloud(out)
            np.testing.assert_allclose(back.points, clean.points, rtol=1e-6, atol=1e-6)
            o3d_back = np.asarray(o3d.io.read_point_cloud(str(out)).points)
            np.testing.assert_allclose(o3d_back, back.points, rtol=1e-6, atol=1e-6)
            if clean.colors is not None:
                np.testing.assert_allclose(back.colors, clean.colors, atol=0.5 / 255 + 1e-12)


@pytest.mark.realdata
def test_mosd_labels_are_read():
    pcd = read_pcd(data_path("pointcloud", "pcl_mOSD", "test0.pcd"))
    assert pcd.data == "binary_compressed" and (pcd.width, pcd.height) == (640, 480)
    labels = pcd.fields["label"]
    assert labels.shape == (640 * 480,) and set(np.unique(labels)) >= {1, 20, 30}


def test_lzf_hand_stream():
    # literal "abc" (ctrl 2), then a back reference of length 3 + 2 = 5 at offset 3:
    # ctrl = (3 << 5) | 0, next byte 2 -> ref = op - 0 - 1 - 2
    stream = np.frombuffer(bytes([2]) + b"abc" + bytes([3 << 5, 2]), dtype=np.uint8)
    out = np.zeros(8, dtype=np.uint8)
    assert _lzf_decompress(stream, out) == 8
    assert out.tobytes() == b"abcabcab"
    bad = np.frombuffer(bytes([3 << 5, 200]), dtype=np.uint8)  # reference before the start
    assert _lzf_decompress(bad, np.zeros(8, np.uint8)) == -1


def test_organized_cloud_keeps_nan_and_shape(tmp_path):
    pts = np.arange(24, dtype=np.float64).reshape(8, 3)
    pts[3] = np.nan
    cloud = PointCloud(pts, shape=(2, 4))
    out = write_point_cloud(tmp_path / "org.pcd", cloud)
    back = read_point_cloud(out)
    assert back.shape == (2, 4)
    np.testing.assert_array_equal(np.isnan(back.points), np.isnan(pts))
    assert len(back.finite()) == 7 and back.finite().shape is None


def _pcd_header(points: int, data: str = "binary") -> bytes:
    return (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA {data}\n"
    ).encode()


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (_pcd_header(10) + b"\x00" * 12, "truncated"),
        (_pcd_header(10**12) + b"\x00" * 12, "truncated"),
        (_pcd_header(10**12, "ascii") + b"1 2 3\n", "cannot hold"),
        (_pcd_header(2, "ascii") + b"1 2 3\n4 5\n", "ascii"),
        (_pcd_header(2, "binary_compressed") + struct.pack("<II", 5, 24) + b"\x00", "truncated"),
        (
            _pcd_header(10**9, "binary_compressed") + struct.pack("<II", 4, 12 * 10**9 % 2**32),
            "expands to",
        ),
        (
            _pcd_header(200, "binary_compressed") + struct.pack("<II", 4, 2400) + b"\0" * 4,
            "cannot expand",
        ),
        (_pcd_header(2, "lzma"), "DATA must be"),
        (b"garbage without a header", "no DATA"),
        (_pcd_header(2).replace(b"SIZE 4 4 4", b"SIZE 4 4"), "one entry per field"),
        (_pcd_header(2).replace(b"POINTS 2", b"POINTS 3"), "WIDTH x HEIGHT"),
    ],
)
def test_corrupt_pcd_is_refused_with_the_file_name(tmp_path, content, match):
    path = tmp_path / "bad.pcd"
    path.write_bytes(content)
    with pytest.raises(FileFormatError, match=match) as info:
        read_point_cloud(path)
    assert "bad.pcd" in str(info.value)


def test_corrupt_lzf_stream(tmp_path):
    body = struct.pack("<II", 3, 24) + bytes([3 << 5, 250, 0])
    path = tmp_path / "lzf.pcd"
    path.write_bytes(_pcd_header(2, "binary_compressed") + body)
    with pytest.raises(FileFormatError, match="LZF"):
        read_point_cloud(path)


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n"
            b"property float x\nproperty float y\nproperty float z\nend_header\n" + b"\0" * 24,
            "at least",
        ),
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 10\n"
            b"property float x\nproperty float y\nproperty float z\nend_header\n" + b"\0" * 24,
            "corrupt PLY|at least",
        ),
        (b"not a ply file at all", "not a PLY"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
            b"property float z\nend_header\n1 2 3\n4 5 oops\n",
            "corrupt PLY",
        ),
        (
            b"ply\nformat ascii 1.0\nelement face 1\nproperty float q\nend_header\n1\n",
            "vertex",
        ),
    ],
)
def test_corrupt_ply_is_refused(tmp_path, content, match):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(FileFormatError, match=match) as info:
        read_point_cloud(path)
    assert "bad.ply" in str(info.value)


def test_missing_and_unknown_files(tmp_path):
    with pytest.raises(FileFormatError, match=r"none\.pcd: no such file"):
        read_point_cloud(tmp_path / "none.pcd")
    with pytest.raises(FileFormatError, match="is a folder; give a point cloud file"):
        read_point_cloud(tmp_path)
    (tmp_path / "cloud.xyz").write_text("0 0 0\n")
    with pytest.raises(FileFormatError, match="extension"):
        read_point_cloud(tmp_path / "cloud.xyz")
    with pytest.raises(InputError, match="extension"):
        write_point_cloud(tmp_path / "cloud.xyz", PointCloud(np.zeros((1, 3))))
    with pytest.raises(InputError, match="PointCloud"):
        write_point_cloud(tmp_path / "c.ply", np.zeros((1, 3)))


def test_empty_cloud_round_trip(tmp_path):
    empty = PointCloud(np.empty((0, 3)))
    for ext in (".ply", ".pcd"):
        back = read_point_cloud(write_point_cloud(tmp_path / f"e{ext}", empty))
        assert len(back) == 0


@pytest.mark.realdata
def test_stanford_ascii_ply_with_faces():
    # the zippered bunny: ascii vertices with extra properties, then a face list
    cloud = read_point_cloud(
        data_path("pointcloud", "stanford_bunny", "reconstruction", "bun_zipper.ply")
    )
    ref = np.asarray(
        o3d.io.read_point_cloud(
            str(data_path("pointcloud", "stanford_bunny", "reconstruction", "bun_zipper.ply"))
        ).points
    )
    assert len(cloud) == 35947
    np.testing.assert_allclose(cloud.points, ref, rtol=1e-6)


# issue 25: PCD header fields beyond what the file can hold (COUNT >= 2**31 escaped
# np.dtype as a ValueError), coordinates with COUNT > 1, and a malformed VIEWPOINT
@pytest.mark.parametrize(
    ("content", "match"),
    [
        (_pcd_header(2).replace(b"COUNT 1 1 1", b"COUNT 2147483648 1 1"), "COUNT 2147483648"),
        (_pcd_header(2).replace(b"COUNT 1 1 1", b"COUNT 1099511627776 1 1"), "more than"),
        (
            _pcd_header(0).replace(b"COUNT 1 1 1", b"COUNT 1 1 100000000"),
            "bytes per point, more than the whole file",
        ),
        (_pcd_header(2).replace(b"COUNT 1 1 1", b"COUNT one 1 1"), "COUNT 'one'"),
        (_pcd_header(2).replace(b"COUNT 1 1 1", b"COUNT 0 1 1"), "COUNT 0"),
        (_pcd_header(2).replace(b"SIZE 4 4 4", b"SIZE 0 4 4"), "SIZE 0"),
        (_pcd_header(2).replace(b"TYPE F F F", b"TYPE Q F F"), "TYPE Q"),
        (_pcd_header(2).replace(b"WIDTH 2", b"WIDTH -2"), "WIDTH must be >= 0"),
        (_pcd_header(2).replace(b"HEIGHT 1", b"HEIGHT 1.5"), "HEIGHT must be an integer"),
        (_pcd_header(2).replace(b"POINTS 2", b"POINTS 2e3"), "POINTS must be an integer"),
        (_pcd_header(2).replace(b"DATA binary", b"DATA"), "DATA must be"),
        (
            _pcd_header(2).replace(b"COUNT 1 1 1", b"COUNT 2 1 1") + b"\0" * 32,
            "field 'x' has COUNT 2; it must be 1",
        ),
        (_pcd_header(2).replace(b"VIEWPOINT 0 0 0 1 0 0 0", b"VIEWPOINT 0 0 0") + b"\0" * 24, "7"),
        (
            _pcd_header(2).replace(b"VIEWPOINT 0 0 0 1", b"VIEWPOINT nan 0 0 1") + b"\0" * 24,
            "VIEWPOINT",
        ),
    ],
)
def test_pcd_header_fields_are_bounded(tmp_path, content, match):
    path = tmp_path / "hostile.pcd"
    path.write_bytes(content)
    with pytest.raises(FileFormatError, match=match) as info:
        read_point_cloud(path)
    assert "hostile.pcd" in str(info.value)


def test_pcd_extra_count_on_other_fields_is_kept(tmp_path):
    # a COUNT > 1 field that is not a coordinate (a descriptor) stays readable
    head = _pcd_header(2).replace(b"FIELDS x y z", b"FIELDS x y z h")
    head = head.replace(b"SIZE 4 4 4", b"SIZE 4 4 4 4").replace(b"TYPE F F F", b"TYPE F F F F")
    head = head.replace(b"COUNT 1 1 1", b"COUNT 1 1 1 3")
    rec = np.arange(12, dtype="<f4").reshape(2, 6)
    path = tmp_path / "desc.pcd"
    path.write_bytes(head + rec.tobytes())
    pcd = read_pcd(path)
    assert pcd.fields["h"].shape == (2, 3)
    np.testing.assert_array_equal(read_point_cloud(path).points, rec[:, :3])


# issue 25: a vertex coordinate (or colour) declared as a list property escaped
# np.column_stack as a ValueError
@pytest.mark.parametrize(
    ("props", "rows", "bad"),
    [
        ("property list uchar float x\nproperty float y\nproperty float z\n", "1 1 2 3\n", "x"),
        ("property float x\nproperty float y\nproperty list uchar float z\n", "1 2 2 3 4\n", "z"),
        (
            "property float x\nproperty float y\nproperty float z\n"
            "property list uchar uchar red\nproperty uchar green\nproperty uchar blue\n",
            "1 2 3 1 9 9 9\n",
            "red",
        ),
    ],
)
def test_ply_list_coordinates_are_refused(tmp_path, props, rows, bad):
    path = tmp_path / "list.ply"
    path.write_text(f"ply\nformat ascii 1.0\nelement vertex 1\n{props}end_header\n{rows}")
    with pytest.raises(FileFormatError, match=f"property {bad} declared as a list") as info:
        read_point_cloud(path)
    assert "list.ply" in str(info.value) and "must be scalar properties" in str(info.value)


# issue 25: paths that cannot name a file are InputErrors, before the OS sees them
@pytest.mark.parametrize(
    "path, words",
    [
        (None, "must be a file or folder path .* got None"),
        (3, "must be a file or folder path .* got 3"),
        ("nul\x00name.pcd", "contains a NUL byte"),
        ("n" * 300 + ".pcd", "file name too long"),
    ],
)
def test_unusable_paths_are_input_errors(path, words, tmp_path):
    for read in (read_pcd, read_point_cloud):
        with pytest.raises(InputError, match=words):
            read(path)
    with pytest.raises(InputError, match=words):
        write_point_cloud(path, PointCloud(np.zeros((1, 3))))


def test_bytes_path_and_binary_flag(tmp_path):
    cloud = PointCloud(np.arange(6.0).reshape(2, 3))
    p = write_point_cloud(str(tmp_path / "c.pcd").encode(), cloud, binary=np.False_)
    assert b"DATA ascii" in p.read_bytes()
    np.testing.assert_array_equal(read_pcd(bytes(p)).fields["x"], [0.0, 3.0])
    with pytest.raises(InputError, match="binary must be True or False"):
        write_point_cloud(tmp_path / "d.pcd", cloud, binary="yes")
    with pytest.raises(FileFormatError, match="no such file"):
        read_pcd(tmp_path / "missing.pcd")


@pytest.mark.parametrize(
    "shape, words",
    [
        ((np.nan, np.nan), r"shape \(H, W\) must be an integer; got nan"),
        ((), r"shape must be \(H, W\), two integers, or None; got \(\)"),
        ((2.0, 1.0), r"shape \(H, W\) must be an integer"),
        (7, "shape must be"),
    ],
)
def test_bad_organized_shape(shape, words):
    with pytest.raises(InputError, match=words):
        PointCloud(np.zeros((2, 3)), shape=shape)
    assert PointCloud(np.zeros((2, 3)), shape=(np.int64(2), 1)).shape == (2, 1)


# --------------------------------------------------------------------------- labels


def _labelled(n=40, seed=0, low=-1):
    rng = np.random.default_rng(seed)
    return PointCloud(
        rng.normal(size=(n, 3)),
        colors=rng.random((n, 3)),
        normals=rng.normal(size=(n, 3)),
        labels=rng.integers(low, 6, n),
    )


@pytest.mark.parametrize("ext", [".ply", ".pcd"])
@pytest.mark.parametrize("binary", [True, False])
def test_labels_round_trip_and_open3d_reads_them(tmp_path, ext, binary):
    """The label field comes back exactly from our reader, from Open3D's tensor reader
    (which keeps every per-point attribute) and, for PLY, from plyfile as int32."""
    cloud = _labelled(low=-1 if ext == ".ply" else 0)
    out = write_point_cloud(tmp_path / f"seg{ext}", cloud, binary=binary)
    back = read_point_cloud(out)
    assert back.labels.dtype == np.int64
    np.testing.assert_array_equal(back.labels, cloud.labels)
    np.testing.assert_allclose(back.points, cloud.points, rtol=1e-6, atol=1e-6)
    t = o3d.t.io.read_point_cloud(str(out))
    np.testing.assert_array_equal(t.point["label"].numpy().ravel(), cloud.labels)
    if ext == ".ply":
        plyfile = pytest.importorskip("plyfile")
        v = plyfile.PlyData.read(str(out))["vertex"].data
        assert v.dtype["label"] == np.dtype("<i4") and v.dtype.names[-1] == "label"
        np.testing.assert_array_equal(v["label"], cloud.labels)
    else:
        head = out.read_bytes()[:400].decode("ascii", "replace")
        # PCL's PointXYZRGBL: x y z (normals) rgb label, label an unsigned 4-byte field
        assert "FIELDS x y z normal_x normal_y normal_z rgb label" in head
        assert "TYPE F F F F F F U U" in head


def test_labels_hand_case_and_what_keeps_them():
    """Hand-written 3-point case: select, finite and concatenate carry the labels;
    concatenate drops them when one cloud has none; floats holding whole numbers are
    taken, anything else refused."""
    c = PointCloud(np.array([[0, 0, 1], [np.nan, 0, 0], [1, 1, 1]]), labels=[5, 6, 7])
    assert c.labels.tolist() == [5, 6, 7]
    assert c.finite().labels.tolist() == [5, 7]
    assert c.select([2, 0]).labels.tolist() == [7, 5]
    assert c.select(np.array([True, False, False]), invert=True).labels.tolist() == [6, 7]
    assert PointCloud.concatenate([c, c]).labels.tolist() == [5, 6, 7] * 2
    assert PointCloud.concatenate([c, c.with_labels(None)]).labels is None
    assert PointCloud(np.zeros((2, 3)), labels=np.array([1.0, 2.0])).labels.dtype == np.int64
    with pytest.raises(InputError, match="labels must be whole numbers"):
        PointCloud(np.zeros((2, 3)), labels=[1.5, 2])
    with pytest.raises(InputError, match=r"labels must have shape \(2,\)"):
        PointCloud(np.zeros((2, 3)), labels=[1, 2, 3])
    with pytest.raises(InputError, match="labels must be integers"):
        PointCloud(np.zeros((2, 3)), labels=["a", "b"])


def test_labels_outside_the_field_are_refused(tmp_path):
    """PCL's label is uint32: -1 (noise) is refused for PCD with the fix; PLY's int32
    takes it but not 2^31."""
    noisy = PointCloud(np.zeros((2, 3)), labels=[-1, 3])
    with pytest.raises(InputError, match=r"PCL's label is unsigned: shift noise"):
        write_point_cloud(tmp_path / "a.pcd", noisy)
    write_point_cloud(tmp_path / "a.ply", noisy)
    assert read_point_cloud(tmp_path / "a.ply").labels.tolist() == [-1, 3]
    with pytest.raises(InputError, match=r"int32, -2147483648..2147483647\); got 2147483648"):
        write_point_cloud(tmp_path / "b.ply", noisy.with_labels([0, 2**31]))


def test_float_and_fractional_label_fields(tmp_path):
    """A float label holding whole numbers (CloudCompare's scalar fields) is read as
    integers; a fractional one is refused with the value."""
    head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
    head += "property float z\nproperty float label\nend_header\n"
    (tmp_path / "f.ply").write_text(head + "0 0 0 3\n1 1 1 4\n")
    assert read_point_cloud(tmp_path / "f.ply").labels.tolist() == [3, 4]
    (tmp_path / "g.ply").write_text(head + "0 0 0 3.5\n1 1 1 4\n")
    with pytest.raises(FileFormatError, match=r"field 'label' holds 3.5"):
        read_point_cloud(tmp_path / "g.ply")


@pytest.mark.realdata
def test_mosd_ground_truth_labels_come_with_the_cloud():
    """The mOSD scene's ground-truth segments (PCL's label field, first in the file)
    are the cloud's labels, as read_pcd and Open3D's tensor reader see them."""
    path = data_path("pointcloud", "pcl_mOSD", "test0.pcd")
    cloud = read_point_cloud(path)
    np.testing.assert_array_equal(cloud.labels, read_pcd(path).fields["label"])
    ref = o3d.t.io.read_point_cloud(str(path)).point["label"].numpy().ravel()
    np.testing.assert_array_equal(cloud.labels, ref)
    assert cloud.shape == (480, 640) and cloud.finite().labels.size == len(cloud.finite())
