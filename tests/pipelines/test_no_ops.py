"""Issue 48, item 3: no silent no-ops in the library behind ``cloud``, ``flow``,
``plane-track``, ``stereo`` and ``bgsub``.

An empty result is an :class:`~robopercept.errors.EmptyResultError` raised before
anything is written; a result that is written but implausible gives a
:class:`~robopercept.errors.RoboperceptWarning`. The same cases through the command
line are in ``tests/cli/test_no_ops_cli.py``.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from robopercept.errors import EmptyResultError, InputError, RoboperceptWarning

# --- cloud: a filter that removes every point ---------------------------------------


def _bunny_like(n: int = 397) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.normal(0.0, 0.03, (n, 3))  # a 397-point blob of a few cm around 0


def test_cloud_pass_through_beside_the_cloud_is_an_empty_result():
    from robopercept.pipelines import process_cloud
    from robopercept.pointcloud import PointCloud

    cloud = PointCloud(_bunny_like())
    with pytest.raises(EmptyResultError) as info:
        process_cloud(cloud, boxes=[("z", 5.0, 6.0)], planes=(1, 0.01))
    msg = str(info.value)
    assert "\n" not in msg
    assert "pass-through z [5, 6] (--pass-through z:5:6) removed all 397 points" in msg
    z = cloud.points[:, 2]
    assert f"z spans {z.min():.4g} to {z.max():.4g}" in msg
    assert "choose a range that overlaps it" in msg
    assert isinstance(info.value, InputError)  # the fix is another argument
    # a second box that empties what the first one kept is named, with its own input
    with pytest.raises(EmptyResultError, match=r"pass-through x \[1, 2\] .* removed all \d+ "):
        process_cloud(cloud, boxes=[("z", -1.0, 1.0), ("x", 1.0, 2.0)])


def test_cloud_without_a_finite_point_is_an_empty_result():
    from robopercept.pipelines import process_cloud
    from robopercept.pointcloud import PointCloud

    with pytest.raises(EmptyResultError, match=r"no finite point \(3 read, 3 not finite\)"):
        process_cloud(PointCloud(np.full((3, 3), np.nan)))
    with pytest.raises(EmptyResultError, match="holds no point"):
        process_cloud(PointCloud(np.zeros((0, 3))))


def test_cloud_that_keeps_a_point_is_processed():
    from robopercept.pipelines import process_cloud
    from robopercept.pointcloud import PointCloud

    pts = np.r_[_bunny_like(), [[0.0, 0.0, 5.5]]]
    res = process_cloud(PointCloud(pts), boxes=[("z", 5.0, 6.0)])
    assert len(res.cloud) == 1 and res.steps[1]["points_out"] == 1


# --- flow: one frame ------------------------------------------------------------------


def test_video_source_with_fewer_frames_than_needed_is_refused(tmp_path):
    from robopercept.imaging import write_image
    from robopercept.sources import VideoSource

    png = tmp_path / "one.png"
    write_image(png, np.zeros((24, 32, 3), np.uint8))
    # ffmpeg reads a still image as a one-frame video: fine by default, refused for 2
    assert len(VideoSource(png)) == 1
    with pytest.raises(EmptyResultError) as info:
        VideoSource(png, min_frames=2)
    msg = str(info.value)
    assert msg.startswith(f"{png} holds 1 frame (a still image?); at least 2 are needed")
    assert "give a video or a folder of 2 images or more" in msg
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        write_image(folder / f"{i}.png", np.zeros((24, 32, 3), np.uint8))
    assert len(VideoSource(folder, min_frames=3)) == 3
    with pytest.raises(EmptyResultError, match=r"gives 1 frame with max_frames \(--max-frames\)"):
        VideoSource(folder, max_frames=1, min_frames=2)
    with pytest.raises(InputError, match="min_frames"):
        VideoSource(folder, min_frames=0)


# --- bgsub (and every video command): a snapshot beyond the last frame ----------------


def test_snapshot_beyond_the_last_frame_warns_once(tmp_path):
    from robopercept.imaging import SnapshotVideoWriter

    out = tmp_path / "o.mp4"
    frame = np.zeros((32, 48, 3), np.uint8)
    with pytest.warns(RoboperceptWarning) as caught:  # on leaving the block
        with SnapshotVideoWriter(out, 10.0, [2, 100, 200]) as writer:
            for i in range(68):
                writer.add(i, frame)
    assert len(caught) == 1
    assert caught[0].filename == __file__  # attributed to the with statement
    msg = str(caught[0].message)
    assert msg == (
        "snapshots 100, 200 (--snapshot) not saved: 68 frames were written, indices up to "
        "67 (snapshots are 0-based frame indices)"
    )
    assert writer.missed_snapshots() == [100, 200]
    assert writer.written == [str(out), str(tmp_path / "o_000002.png")]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        writer.close()  # closing again: no second warning


def test_snapshots_all_reached_or_an_error_in_the_block_do_not_warn(tmp_path):
    from robopercept.imaging import SnapshotVideoWriter

    frame = np.zeros((32, 48, 3), np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with SnapshotVideoWriter(tmp_path / "a.mp4", 10.0, [1]) as writer:
            writer.add(0, frame)
            writer.add(1, frame)
        assert writer.missed_snapshots() == []
        with (
            pytest.raises(KeyboardInterrupt),
            SnapshotVideoWriter(tmp_path / "b.mp4", 10.0, [5]) as writer,
        ):
            writer.add(0, frame)
            raise KeyboardInterrupt  # an interrupted run: the missing snapshot is no news
    assert (tmp_path / "b.mp4").exists()


# --- stereo: left and right swapped ---------------------------------------------------


def _textured_pair(shift: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A smooth random texture and its true right view (every point ``shift`` px
    further left)."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(1)
    scene = gaussian_filter(rng.uniform(0, 1, (96, 200)), 1.0)
    scene = (scene - scene.min()) / np.ptp(scene)
    return scene[:, 20:180], scene[:, 20 + shift : 180 + shift]


@pytest.mark.parametrize("method", ["bm", "sgm"])
def test_a_swapped_pair_warns_and_the_right_order_does_not(method):
    from robopercept.depth import block_matching, semi_global_matching

    left, right = _textured_pair()

    def match(a, b, **kw):
        if method == "bm":
            return block_matching(a, b, 16, 7, **kw)
        return semi_global_matching(a, b, 16, **kw)

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        good = match(left, right, lr_check=1.0)
        match(left, right)  # no left-right check: the order is tested every time
    assert np.nanmedian(good) == pytest.approx(6.0, abs=0.5)
    for kw in ({"lr_check": 1.0}, {}):
        with pytest.warns(RoboperceptWarning) as caught:
            match(right, left, **kw)
        assert len(caught) == 1
        msg = str(caught[0].message)
        assert msg.startswith("left and right look swapped (")
        assert ("% of the pixels valid; " in msg) == bool(kw)
        assert "pass the left camera's image first (robopercept stereo LEFT RIGHT)" in msg
        assert "\n" not in msg


def test_order_scores_separate_the_two_orders():
    from robopercept.depth.stereo import _order_scores
    from robopercept.imaging.color import gray_255

    left, right = _textured_pair()
    L, R = gray_255(left, "left"), gray_255(right, "right")
    given, exchanged = _order_scores(L, R, 16)
    assert given > 0.9 and exchanged < given - 0.3  # random texture: chance matches
    assert _order_scores(R, L, 16) == (exchanged, given)
    # independent noise matches neither way; a flat pair nothing; too small: no verdict
    rng = np.random.default_rng(2)
    a, b = _order_scores(rng.uniform(0, 255, (60, 100)), rng.uniform(0, 255, (60, 100)), 16)
    assert abs(a - b) < 0.1
    assert _order_scores(np.full((60, 100), 9.0), np.full((60, 100), 9.0), 16) == (0.0, 0.0)
    assert _order_scores(L[:, :40], R[:, :40], 16) is None  # 40 px for 16 disparities


@pytest.mark.realdata
def test_swapped_middlebury_cones_warns_with_the_valid_share():
    """The issue's case: cones swapped keep 48.5 % of the pixels by SGM with the check,
    and the quick test prefers the exchanged order 95 % to 35 %."""
    from robopercept.depth import semi_global_matching
    from robopercept.imaging import read_image
    from tests.conftest import data_path

    folder = data_path("stereo", "middlebury2003_cones")
    left = read_image(folder / "left.png", mode="gray")
    right = read_image(folder / "right.png", mode="gray")
    with pytest.warns(RoboperceptWarning, match=r"look swapped \(48\.\d% of the pixels valid"):
        disp = semi_global_matching(right, left, 64, lr_check=1.0)
    assert 0.45 < np.isfinite(disp).mean() < 0.52
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        disp = semi_global_matching(left, right, 64, lr_check=1.0)
    assert np.isfinite(disp).mean() > 0.85


# --- plane-track: scattered green specks are no board ---------------------------------


def _specks(frame, share: float = 0.08, seed: int = 0):
    """``frame`` with its colour image grey except ``share`` of its pixels, at random,
    green: specks spread over the wall and the floor, no board."""
    rng = np.random.default_rng(seed)
    color = np.full_like(frame.color, 128)
    h, w = color.shape[:2]
    k = rng.choice(h * w, int(share * h * w), replace=False)
    color.reshape(-1, 3)[k] = (40, 200, 40)
    return dataclasses.replace(frame, color=color, ground_truth={})


def _scene(n: int = 3):
    from robopercept.sources import SyntheticRGBDScene

    return SyntheticRGBDScene(
        n_frames=n, depth_size=(212, 120), color_size=(320, 180), distractor="none"
    )


def test_scattered_specks_are_no_board_and_the_board_is():
    from robopercept.pipelines import PlaneMeasurer, PlaneTrackerConfig

    frame = _scene(1).frame(0)
    board = PlaneMeasurer().measure(frame)
    assert board.found and board.solidity > 0.35
    specks = PlaneMeasurer().measure(_specks(frame))
    # the specks are many and lie on the wall: a plane with enough inliers, not a board
    assert specks.n_colored >= 200 and not specks.found
    assert specks.solidity < 0.1 and specks.inlier_points.shape == (0, 3)
    # min_solidity=0 gives the plane of the specks back (the former behaviour)
    loose = PlaneMeasurer(PlaneTrackerConfig(min_solidity=0.0).measurer).measure(_specks(frame))
    assert loose.found and loose.inliers >= 200
    with pytest.raises(InputError, match="min_solidity"):
        PlaneTrackerConfig(min_solidity=1.5)


def test_pixel_solidity_equals_scikit_image():
    """The solidity is scikit-image's ``regionprops(mask)[0].solidity`` to 1e-3 on
    filled rectangles, rectangles with stray pixels, and scattered pixels."""
    measure = pytest.importorskip("skimage.measure")
    from robopercept.pipelines.plane_measure import _pixel_solidity

    rng = np.random.default_rng(0)
    for trial in range(12):
        mask = np.zeros((60, 80), bool)
        if trial % 3 == 0:
            mask[rng.integers(0, 60, 300), rng.integers(0, 80, 300)] = True
        else:
            y, x = rng.integers(0, 20, 2)
            mask[y : y + rng.integers(3, 40), x : x + rng.integers(3, 50)] = True
            if trial % 3 == 2:
                mask[rng.integers(0, 60, 20), rng.integers(0, 80, 20)] = True
        ours = _pixel_solidity(np.flatnonzero(mask), 80)
        assert ours == pytest.approx(
            measure.regionprops(mask.astype(np.uint8))[0].solidity, abs=1e-3
        )
    assert _pixel_solidity(np.arange(5, 25), 80) == pytest.approx(1.0)  # a row: a line


def test_run_without_a_board_warns_once_and_writes_unmeasured_rows(tmp_path):
    from robopercept.pipelines.plane_outputs import run_plane_tracking

    frames = [_specks(f, seed=f.index) for f in _scene(3)]
    with pytest.warns(RoboperceptWarning) as caught:
        summary = run_plane_tracking(frames, tmp_path, video=False, progress=False)
    ours = [w for w in caught if issubclass(w.category, RoboperceptWarning)]
    assert len(ours) == 1
    msg = str(ours[0].message)
    assert msg.startswith("no board found in any of the 3 frames: the board-coloured pixels ")
    assert "scattered specks" in msg and "--hsv-low, --hsv-high" in msg
    assert (summary.frames, summary.measured_frames) == (3, 0)
    rows = (tmp_path / "plane.csv").read_text().splitlines()[1:]
    assert len(rows) == 3 and all(r.split(",")[3] == "0" for r in rows)  # measured 0


def test_run_with_too_few_board_pixels_says_so(tmp_path):
    from robopercept.pipelines.plane_outputs import run_plane_tracking

    frames = [_specks(f, share=0.01) for f in _scene(2)]
    with pytest.warns(RoboperceptWarning, match=r"too few board-coloured pixels \(\d+ at most"):
        run_plane_tracking(frames, tmp_path, video=False, progress=False)


def test_a_run_that_finds_the_board_does_not_warn(tmp_path):
    from robopercept.pipelines.plane_outputs import run_plane_tracking

    with warnings.catch_warnings():
        warnings.simplefilter("error", RoboperceptWarning)
        summary = run_plane_tracking(list(_scene(3)), tmp_path, video=False, progress=False)
    assert summary.measured_frames == 3


def test_the_frame_without_a_board_says_so_on_the_video(monkeypatch):
    from robopercept.pipelines import PlaneTracker, plane_outputs

    lines: list[str] = []
    draw = plane_outputs.draw_text
    monkeypatch.setattr(
        plane_outputs,
        "draw_text",
        lambda img, text, *a, **k: lines.append(text) or draw(img, text, *a, **k),
    )
    frame = _specks(_scene(1).frame(0))
    result = PlaneTracker().process(frame)
    assert not result.measured and result.solidity < 0.1
    plane_outputs.annotate_frame(frame, result)
    assert lines[-1].startswith("frame 0  lost  no board found")
    board = _scene(1).frame(0)
    plane_outputs.annotate_frame(board, PlaneTracker().process(board))
    assert "inliers" in lines[-1] and "no board" not in lines[-1]
