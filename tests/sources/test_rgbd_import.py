"""rgbd-import's library: presets, depth decoding (hand cases, Open3D parity), the
layouts it recognises, the 16-bit PGM read, bad input, and PCL's real Kinect frames
against PCL's own back-projected clouds."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging.io import read_image, write_image
from robopercept.sources import (
    CAMERA_PRESETS,
    TUMFolderSource,
    camera_preset,
    import_rgbd_folder,
)
from robopercept.sources.rgbd_import import decode_depth, depth_to_units, find_rgbd_pairs
from tests.conftest import data_path


def write_pgm16(path, values):
    """A binary 16-bit PGM written by hand (P5, maxval 65535, big-endian as the format
    says), so the reader is checked against the bytes, not against itself."""
    h, w = values.shape
    path.write_bytes(f"P5\n{w} {h}\n65535\n".encode() + values.astype(">u2").tobytes())


def pair_folder(tmp_path, names, shape=(6, 8), depth_value=5000):
    """A folder with colour/depth pairs named as given ((colour, depth) file names)."""
    src = tmp_path / "src"
    src.mkdir()
    rng = np.random.default_rng(0)
    for i, (cname, dname) in enumerate(names):
        write_image(src / cname, rng.integers(0, 255, (*shape, 3), dtype=np.uint8))
        depth = np.full(shape, depth_value + i, np.uint16)
        if dname.endswith(".pgm"):
            write_pgm16(src / dname, depth)
        else:
            write_image(src / dname, depth)
    return src


class TestPresets:
    def test_tum_published_numbers(self):
        # vision.in.tum.de/data/datasets/rgbd-dataset/file_formats#intrinsic_camera_calibration
        fr1, fr2, fr3 = (camera_preset(n) for n in ("fr1", "fr2", "fr3"))
        assert (fr1.fx, fr1.fy, fr1.cx, fr1.cy) == (517.3, 516.5, 318.6, 255.3)
        assert fr1.coeffs == (0.2624, -0.9531, -0.0054, 0.0026, 1.1633)
        assert fr1.model == "brown_conrady"  # OpenCV's k1 k2 p1 p2 k3
        assert (fr2.fx, fr2.fy, fr2.cx, fr2.cy) == (520.9, 521.0, 325.1, 249.7)
        assert fr2.coeffs == (0.2312, -0.7849, -0.0033, -0.0001, 0.9172)
        assert (fr3.fx, fr3.fy, fr3.cx, fr3.cy, fr3.model) == (535.4, 539.2, 320.1, 247.6, "none")
        ros = camera_preset("ros-default")
        assert (ros.fx, ros.fy, ros.cx, ros.cy) == (525.0, 525.0, 319.5, 239.5)
        assert all((k.width, k.height) == (640, 480) for k in CAMERA_PRESETS.values())

    def test_unknown_preset_lists_the_choices(self):
        with pytest.raises(InputError, match="fr1, fr2, fr3, ros-default"):
            camera_preset("fr4")

    def test_preset_written_to_camera_json(self, tmp_path):
        src = pair_folder(tmp_path, [("a_color.png", "a_depth.png")], shape=(480, 640))
        import_rgbd_folder(src, tmp_path / "out", preset="fr2")
        cam = json.loads((tmp_path / "out" / "camera.json").read_text())
        for which in ("depth", "color"):
            c = cam[which]
            assert (c["fx"], c["fy"], c["cx"], c["cy"]) == (520.9, 521.0, 325.1, 249.7)
            assert c["coeffs"] == [0.2312, -0.7849, -0.0033, -0.0001, 0.9172]
        assert cam["T_color_depth"] == np.eye(4).tolist()
        assert cam["depth_scale"] == pytest.approx(1 / 5000)

    def test_preset_refuses_another_image_size(self, tmp_path):
        src = pair_folder(tmp_path, [("a_color.png", "a_depth.png")], shape=(6, 8))
        with pytest.raises(InputError, match="--intrinsics"):
            import_rgbd_folder(src, tmp_path / "out", preset="fr1")
        assert not (tmp_path / "out").exists()  # nothing written before the camera is known


class TestDecodeDepth:
    def test_linear_hand_values(self):
        z = decode_depth(np.array([[5000, 2500, 0, 65535]], np.uint16))
        np.testing.assert_array_equal(z, [[1.0, 0.5, 0.0, 13.107]])
        z = decode_depth(np.array([[1.5, np.nan, -1.0, np.inf]], np.float32), units_per_metre=1)
        np.testing.assert_array_equal(z, [[1.5, 0.0, 0.0, 0.0]])  # no measurement -> 0

    def test_sun_rotates_three_bits(self):
        # (v >> 3) | (v << 13) in 16 bits: 1000 mm stored as 8000; v = 1 wraps to 8192 mm
        z = decode_depth(np.array([[8000, 1, 0]], np.uint16), "sun")
        np.testing.assert_allclose(z, [[1.0, 8.192, 0.0]])

    def test_nyu_swaps_bytes_then_disparity_to_metres(self):
        # disparity 1024 = 0x0400 is stored little-endian, read as 0x0004
        v = np.array([[0x0004, 0xFF07, 0x0000]], np.uint16)  # 1024, 2047, 0
        z = decode_depth(v, "nyu")
        np.testing.assert_allclose(z, [[351.3 / (1092.5 - 1024), 0.0, 351.3 / 1092.5]])

    def test_bad_input(self):
        with pytest.raises(InputError, match="single-channel"):
            decode_depth(np.zeros((2, 2, 3), np.uint16))
        with pytest.raises(InputError, match="--depth-encoding"):
            decode_depth(np.zeros((2, 2), np.uint16), "kinect")
        with pytest.raises(InputError, match="--depth-scale"):
            decode_depth(np.zeros((2, 2), np.uint16), units_per_metre=0)
        with pytest.raises(InputError, match="16-bit integer"):
            decode_depth(np.zeros((2, 2), np.float32), "sun")

    @pytest.mark.realdata
    @pytest.mark.parametrize(
        ("name", "encoding", "color_ext", "depth_ext", "factory", "trunc", "tol"),
        [
            # Open3D's defaults: TUM cut at 4 m, SUN at 7 m; NYU kept in whole millimetres
            ("TUM", "linear", "png", "png", "create_from_tum_format", 4.0, 1e-6),
            ("SUN", "sun", "jpg", "png", "create_from_sun_format", 7.0, 1e-6),
            ("NYU", "nyu", "ppm", "pgm", "create_from_nyu_format", 10.0, 5e-4),
        ],
    )
    def test_matches_open3d(self, name, encoding, color_ext, depth_ext, factory, trunc, tol):
        o3d = pytest.importorskip("open3d")
        folder = data_path("rgbd", "single_frames_open3d")
        raw = read_image(folder / f"{name}_depth.{depth_ext}")
        color = read_image(folder / f"{name}_color.{color_ext}")
        ref = getattr(o3d.geometry.RGBDImage, factory)(
            o3d.geometry.Image(color), o3d.geometry.Image(raw)
        )
        ref = np.asarray(ref.depth, dtype=np.float64)
        z = decode_depth(raw, encoding)
        kept = ref > 0
        assert kept.mean() > 0.5
        np.testing.assert_allclose(z[kept], ref[kept], rtol=0, atol=tol)
        dropped = (z > 0) & ~kept  # only Open3D's depth cut-off differs
        assert (z[dropped] > trunc - 1e-3).all()


def test_depth_to_units_rounds_and_counts_overflow():
    d, n = depth_to_units(np.array([[1.00001, 0.0, 13.2, np.nan, -2.0]]), 5000)
    assert d.dtype == np.uint16
    assert d.tolist() == [[5000, 0, 0, 0, 0]] and n == 1


class TestPGM:
    def test_16bit_pgm_reads_as_uint16(self, tmp_path):
        values = np.array([[0, 1, 255], [256, 40000, 65535]], np.uint16)
        write_pgm16(tmp_path / "d.pgm", values)
        got = read_image(tmp_path / "d.pgm")
        assert got.dtype == np.uint16
        np.testing.assert_array_equal(got, values)

    def test_pgm_depth_imported_in_metres(self, tmp_path):
        src = tmp_path / "src"
        (src / "color").mkdir(parents=True)
        (src / "depth").mkdir()
        depth = np.zeros((4, 5), np.uint16)
        depth[2, 3] = 7321  # 7321 / 5000 = 1.4642 m
        write_pgm16(src / "depth" / "1.pgm", depth)
        write_image(src / "color" / "1.png", np.zeros((4, 5, 3), np.uint8))
        res = import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5))
        assert (res.layout, res.frames, res.skipped) == ("subfolders", 1, ())
        frame = next(iter(TUMFolderSource(tmp_path / "out")))
        assert frame.depth.dtype == np.uint16
        assert frame.depth[2, 3] == 7321  # integer depth is kept exactly
        assert frame.depth[2, 3] * frame.depth_scale == pytest.approx(1.4642, abs=1e-12)
        assert frame.depth[0, 0] == 0  # no measurement stays 0

    def test_hand_written_folder_with_pgm_depth_is_not_skipped(self, tmp_path):
        # the issue: camera.json written by hand, depth.txt naming 16-bit PGMs, every
        # frame refused as "int32"
        (tmp_path / "rgb").mkdir()
        (tmp_path / "depth").mkdir()
        depth = np.arange(12, dtype=np.uint16).reshape(3, 4) * 5000
        write_pgm16(tmp_path / "depth" / "0.pgm", depth)
        write_image(tmp_path / "rgb" / "0.png", np.zeros((3, 4, 3), np.uint8))
        (tmp_path / "rgb.txt").write_text("0.0 rgb/0.png\n")
        (tmp_path / "depth.txt").write_text("0.0 depth/0.pgm\n")
        cam = {"width": 4, "height": 3, "fx": 3.0, "fy": 3.0, "cx": 1.5, "cy": 1.0}
        (tmp_path / "camera.json").write_text(
            json.dumps(
                {
                    "depth": cam,
                    "color": cam,
                    "T_color_depth": np.eye(4).tolist(),
                    "depth_scale": 0.0002,
                }
            )
        )
        src = TUMFolderSource(tmp_path)
        (frame,) = list(src)
        assert src.skipped == []
        np.testing.assert_array_equal(frame.depth * frame.depth_scale, np.arange(12).reshape(3, 4))

    @pytest.mark.realdata
    def test_real_16bit_pgm_against_its_bytes(self):
        path = data_path("rgbd", "rgbd5_poses_slambook2", "depth", "1.pgm")
        header = b"P5 640 480 65535\n"  # maxval 65535: two big-endian bytes a pixel
        data = path.read_bytes()
        assert data.startswith(header)
        ref = np.frombuffer(data[len(header) :], ">u2").reshape(480, 640)
        got = read_image(path)
        assert got.dtype == np.uint16
        np.testing.assert_array_equal(got, ref)


def test_float_tiff_depth_in_metres(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    src = tmp_path / "src"
    src.mkdir()
    z = np.full((4, 5), 1.25, np.float32)
    z[0, 0] = np.nan
    tifffile.imwrite(src / "f_depth.tiff", z)
    write_image(src / "f_rgb.png", np.zeros((4, 5, 3), np.uint8))
    res = import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5), depth_scale=1)
    assert res.depth_scale == pytest.approx(1 / 5000)  # float depth stored in TUM units
    frame = next(iter(TUMFolderSource(tmp_path / "out")))
    assert frame.depth[1, 1] == 6250 and frame.depth[0, 0] == 0


class TestLayouts:
    @pytest.mark.parametrize(
        "names",
        [
            [("1.png", "1_depth.png"), ("2.png", "2_depth.png")],
            [("NYU_color.ppm", "NYU_depth.pgm"), ("TUM_color.png", "TUM_depth.png")],
            [("a_rgb.tiff", "a_depth.tiff"), ("b_rgb.tiff", "b_depth.tiff")],
            [("x-color.png", "x-depth.png"), ("y-color.png", "y-depth.png")],
        ],
    )
    def test_image_pairs(self, tmp_path, names):
        src = pair_folder(tmp_path, names)
        (src / "notes.xml").write_text("<x/>")  # other files are ignored
        layout, pairs = find_rgbd_pairs(src)
        assert layout == "pairs"
        assert [(p.color.name, p.depth.name) for p in pairs] == names

    def test_natural_order_and_match(self, tmp_path):
        names = [(f"{i}.png", f"{i}_depth.png") for i in (10, 2, 1)]
        src = pair_folder(tmp_path, names)
        _, pairs = find_rgbd_pairs(src)
        assert [p.name for p in pairs] == ["1", "2", "10"]
        _, pairs = find_rgbd_pairs(src, match="1*")
        assert [p.name for p in pairs] == ["1", "10"]
        with pytest.raises(FileFormatError, match="--match"):
            find_rgbd_pairs(src, match="zzz")

    def test_tum_lists_keep_the_depth_timestamps(self, tmp_path):
        src = tmp_path / "tum"
        (src / "rgb").mkdir(parents=True)
        (src / "depth").mkdir()
        rgb_lines, depth_lines = ["# colour"], ["# depth"]
        for i, (tc, td) in enumerate([(10.00, 10.01), (10.033, 10.045), (10.5, 11.0)]):
            write_image(src / "rgb" / f"{tc:.6f}.png", np.full((4, 5, 3), i, np.uint8))
            write_image(src / "depth" / f"{td:.6f}.png", np.full((4, 5), 1000 + i, np.uint16))
            rgb_lines.append(f"{tc:.6f} rgb/{tc:.6f}.png")
            depth_lines.append(f"{td:.6f} depth/{td:.6f}.png")
        (src / "rgb.txt").write_text("\n".join(rgb_lines))
        (src / "depth.txt").write_text("\n".join(depth_lines))
        res = import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5))
        assert (res.layout, res.frames) == ("tum-lists", 2)  # 11.0 has no colour within 20 ms
        frames = list(TUMFolderSource(tmp_path / "out"))
        assert [f.timestamp for f in frames] == [10.01, 10.045]
        assert [int(f.depth[0, 0]) for f in frames] == [1000, 1001]
        assert [int(f.color[0, 0, 0]) for f in frames] == [0, 1]  # its own colour image

    @pytest.mark.parametrize("depth_first", [False, True])
    def test_association_list_either_column_order(self, tmp_path, depth_first):
        src = pair_folder(tmp_path, [("c1.png", "d1_depth.png"), ("c2.png", "d2_depth.png")])
        (src / "rgb").mkdir()
        (src / "depth").mkdir()
        for p in list(src.iterdir()):
            if p.is_file():
                p.rename(src / ("depth" if "depth" in p.name else "rgb") / p.name)
        rows = [(1.0, "rgb/c2.png", 1.01, "depth/d2_depth.png")]
        rows.append((2.0, "rgb/c1.png", 2.01, "depth/d1_depth.png"))
        text = "\n".join(
            f"{t2} {f2} {t1} {f1}" if depth_first else f"{t1} {f1} {t2} {f2}"
            for t1, f1, t2, f2 in rows
        )
        (src / "associations.txt").write_text("# t rgb t depth\n" + text)
        layout, pairs = find_rgbd_pairs(src)
        assert layout == "tum-associations"
        assert [(p.color.name, p.depth.name, p.timestamp) for p in pairs] == [
            ("c2.png", "d2_depth.png", 1.01),
            ("c1.png", "d1_depth.png", 2.01),
        ]

    def test_association_list_without_a_depth_column(self, tmp_path):
        src = tmp_path / "src"
        src.mkdir()
        (src / "associate.txt").write_text("1.0 a.png 1.0 b.png\n")
        with pytest.raises(FileFormatError, match=r"associate\.txt:1: cannot tell"):
            find_rgbd_pairs(src)


class TestBadInput:
    def test_missing_folder_and_empty_folder(self, tmp_path):
        with pytest.raises(FileFormatError, match="not a folder"):
            import_rgbd_folder(tmp_path / "nope", tmp_path / "out", preset="fr1")
        with pytest.raises(FileFormatError, match=r"no colour/depth image pairs.*rgb\.txt"):
            import_rgbd_folder(tmp_path, tmp_path / "out", preset="fr1")

    def test_camera_flags(self, tmp_path):
        src = pair_folder(tmp_path, [("a.png", "a_depth.png")])
        with pytest.raises(InputError, match=r"--preset .* or --intrinsics"):
            import_rgbd_folder(src, tmp_path / "o")
        with pytest.raises(InputError, match="exactly one"):
            import_rgbd_folder(src, tmp_path / "o", preset="fr1", intrinsics=(1, 1, 1, 1))
        with pytest.raises(
            InputError, match=r"--intrinsics fx,fy \(pixels\) must be > 0; got -1, 1"
        ):
            import_rgbd_folder(src, tmp_path / "o", intrinsics=(-1, 1, 1, 1))

    def test_flag_values(self, tmp_path):
        src = pair_folder(tmp_path, [("a.png", "a_depth.png")])
        k = {"intrinsics": (5, 5, 2, 1.5)}
        with pytest.raises(InputError, match="--depth-scale applies to --depth-encoding linear"):
            import_rgbd_folder(src, tmp_path / "o", depth_scale=1000, depth_encoding="sun", **k)
        with pytest.raises(InputError, match="--depth-scale"):
            import_rgbd_folder(src, tmp_path / "o", depth_scale=-5, **k)
        with pytest.raises(InputError, match="OUT_DIR must differ"):
            import_rgbd_folder(src, src, **k)

    def test_unreadable_pairs_are_skipped_and_named(self, tmp_path):
        names = [("a.png", "a_depth.png"), ("b.png", "b_depth.png"), ("c.png", "c_depth.png")]
        src = pair_folder(tmp_path, names)
        (src / "b_depth.png").write_bytes(b"not a png")
        write_image(src / "c.png", np.zeros((3, 3, 3), np.uint8))  # not the depth's size
        with pytest.warns(UserWarning, match="skipping"):
            res = import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5))
        assert res.frames == 1
        assert [n for n, _ in res.skipped] == ["b", "c"]
        assert "cannot decode" in res.skipped[0][1] and "same size" in res.skipped[1][1]
        assert len(TUMFolderSource(tmp_path / "out")) == 1

    def test_nothing_readable_writes_nothing(self, tmp_path):
        src = pair_folder(tmp_path, [("a.png", "a_depth.png")])
        write_image(src / "a_depth.png", np.zeros((6, 8), np.uint8))  # an 8-bit picture
        with pytest.warns(UserWarning), pytest.raises(FileFormatError, match="8-bit depth"):
            import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5))
        assert not (tmp_path / "out").exists()

    def test_implausible_depth_scale_is_warned_about(self, tmp_path):
        src = pair_folder(tmp_path, [("a.png", "a_depth.png")], depth_value=3000)
        with pytest.warns(UserWarning, match="check --depth-scale"):
            import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5), depth_scale=1)


@pytest.mark.realdata
def test_pcl_kinect_frames_match_pcl_clouds(tmp_path):
    """PCL's grabber sequence (16-bit TIFF depth in mm, fx = fy = 525, cx = 320, cy = 240
    in its .xml) imported, read back, and deprojected: the points are PCL's own organized
    clouds (.pcd) of the same frames, to float32 rounding."""
    from robopercept.depth import depth_to_points
    from robopercept.pointcloud import read_point_cloud

    folder = data_path("rgbd", "pcl_kinect_grabber_sequence")
    res = import_rgbd_folder(
        folder, tmp_path / "out", intrinsics=(525, 525, 320, 240), depth_scale=1000
    )
    assert (res.layout, res.frames, res.skipped, res.depth_scale) == ("pairs", 3, (), 0.001)
    pcds = sorted(folder.glob("*.pcd"))
    for frame, pcd in zip(TUMFolderSource(tmp_path / "out"), pcds, strict=True):
        ours = depth_to_points(frame.depth, frame.depth_intrinsics, frame.depth_scale)
        ref = read_point_cloud(pcd).points.reshape(480, 640, 3)
        valid = np.isfinite(ref).all(-1)
        np.testing.assert_array_equal(np.isfinite(ours).all(-1), valid)
        assert valid.mean() > 0.8
        np.testing.assert_allclose(ours[valid], ref[valid], rtol=0, atol=1e-6)  # float32 PCD


@pytest.mark.parametrize(
    ("content", "what"),
    [
        (None, "missing"),
        ("{not json", "not valid JSON"),
        ('{"depth": {}, "color": {}}', "field 'T_color_depth' missing"),
        (
            json.dumps(
                {
                    "depth": {"width": 4, "height": 3, "fx": 1, "fy": 1, "cx": 0},
                    "color": {},
                    "T_color_depth": np.eye(4).tolist(),
                    "depth_scale": 0.001,
                }
            ),
            "bad 'depth' camera ('cy')",
        ),
        (
            json.dumps({"depth": {}, "color": {}, "T_color_depth": [[1]], "depth_scale": 1e-3}),
            "bad 'depth' camera",
        ),
    ],
)
def test_camera_json_errors_name_the_fields_and_the_fix(tmp_path, content, what):
    from robopercept.sources import read_camera_json

    if content is not None:
        (tmp_path / "camera.json").write_text(content)
    with pytest.raises(FileFormatError) as info:
        read_camera_json(tmp_path / "camera.json")
    msg = str(info.value)
    assert what in msg
    for needle in (
        "width, height, fx, fy, cx, cy",
        "'T_color_depth'",
        "'depth_scale'",
        "metres per depth unit",
        "robopercept rgbd-import",
        "docs/tracking.md",
    ):
        assert needle in msg


# issue 25: names, patterns, paths and scalars of the wrong type are InputErrors
class TestIssue25:
    def test_preset_of_another_type(self):
        with pytest.raises(InputError, match=r"unknown camera preset \['fr1'\]"):
            camera_preset(["fr1"])

    @pytest.mark.parametrize(
        "kwargs, words",
        [
            ({"match": ["x"]}, r"match \(--match\) must be a shell pattern string"),
            ({"max_difference": [1, 2]}, r"max_difference \(seconds\) must be a real"),
            ({"fps": 1 + 1j}, "--fps must be a real number"),
            ({"progress": "yes"}, "progress must be True or False"),
            ({"depth_encoding": ["sun"]}, r"must be one of linear, sun, nyu \(--depth-encoding\)"),
            ({"depth_scale": "1000"}, r"--depth-scale\) must be a real number"),
            ({"preset": 3}, "unknown camera preset 3"),
            ({"intrinsics": (5, 5, [2], 1.5)}, "--intrinsics fx,fy,cx,cy must be 4 finite"),
        ],
    )
    def test_bad_arguments(self, tmp_path, kwargs, words):
        src = pair_folder(tmp_path, [("a.png", "a_depth.png")])
        call = {"intrinsics": (5, 5, 2, 1.5), **kwargs}
        if "preset" in kwargs:
            del call["intrinsics"]
        with pytest.raises(InputError, match=words):
            import_rgbd_folder(src, tmp_path / "o", **call)
        assert not (tmp_path / "o").exists()

    @pytest.mark.parametrize(
        "src, out, words",
        [
            (None, "o", "SRC_DIR must be a file or folder path"),
            ("s", "o" * 300, "OUT_DIR: file name too long"),
            ("s", "nul\x00", "OUT_DIR contains a NUL byte"),
        ],
    )
    def test_bad_paths(self, tmp_path, src, out, words):
        src = pair_folder(tmp_path, [("a.png", "a_depth.png")]) if src else src
        with pytest.raises(InputError, match=words):
            import_rgbd_folder(src, str(tmp_path / out), intrinsics=(5, 5, 2, 1.5))

    def test_decode_and_units_refuse_non_numbers(self):
        with pytest.raises(InputError, match=r"--depth-scale\) must be a real number"):
            decode_depth(np.ones((2, 2), np.uint16), "linear", None)
        with pytest.raises(InputError, match="depth must be numeric"):
            decode_depth(np.array([["a"]]))
        with pytest.raises(InputError, match="metres must hold real numbers"):
            depth_to_units([["a"]], 5000)
        # a huge scale saturates to "out of range", not to an overflow warning or error
        d, n = depth_to_units(np.array([[10.0]]), 1e308)
        assert d.tolist() == [[0]] and n == 1
