"""Checkpoints of the built models under hostile files (issue 47).

One validation (``check_state_dict``, run by ``load_checkpoint(path, model)`` and by
``load_built_model``, which every detector, segmenter, pose and point-cloud loader
goes through) checks every field before anything is built at full size: weights that
do not fit the model (R40), damaged ``settings`` and ``classes`` (R41), absurd
integer settings (R47), NaN or infinite weights (R45) are a FileFormatError naming the
file (and the first mismatched tensor), never a torch RuntimeError, a TypeError or a
hang. A failed checkpoint write (a full disk) is a WriteError and leaves the previous
checkpoint intact (R55).
"""

from __future__ import annotations

import errno
import io
import math
import os
import signal
import time

import pytest

torch = pytest.importorskip("torch")

from torch import nn  # noqa: E402

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.fileio import WriteError  # noqa: E402
from robopercept.nn.cloud.train import build_cloud_model, load_cloud_model, save_cloud_model  # noqa: E402
from robopercept.nn.detection.zoo import (  # noqa: E402
    DETECTORS,
    build_detector,
    load_detector,
    save_detector,
)
from robopercept.nn.pose.networks import (  # noqa: E402
    DeepPose,
    DeepPoseRefiner,
    HRNet,
    SimpleBaseline,
    build_pose_model,
    load_pose_model,
    save_pose_model,
)
from robopercept.nn.segmentation.networks import (  # noqa: E402
    SEGMENTERS,
    NaiveFCN,
    UNet,
    build_segmenter,
    load_segmenter,
    save_segmenter,
)
from robopercept.nn.skeleton import MPII_16  # noqa: E402
from robopercept.nn.train import checkpoint as ckpt  # noqa: E402
from robopercept.nn.train.checkpoint import (  # noqa: E402
    check_state_dict,
    load_built_model,
    load_checkpoint,
    save_checkpoint,
)

pytestmark = pytest.mark.usefixtures("torch_one_thread")


# ----------------------------------------------------------------------------- files
@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """One small checkpoint of each family, written by its own saver."""
    d = tmp_path_factory.mktemp("ckpt")
    out = {}
    out["detector"] = save_detector(
        d / "det.pt", build_detector("fcos", 2, width=4), "fcos", {"width": 4}, ["a", "b"]
    )
    out["segmenter"] = save_segmenter(
        d / "seg.pt", UNet(3, 3, 4, 2), "unet", {"width": 4, "depth": 2}, ["a", "b"]
    )
    out["pose"] = save_pose_model(
        d / "pose.pt", SimpleBaseline(16, 2), "heatmap", {"width": 2}, MPII_16
    )
    deep = build_pose_model("deeppose", 16, image_size=(32, 32), width=2, hidden=8)
    out["deeppose"] = save_pose_model(
        d / "deeppose.pt",
        deep,
        "deeppose",
        {"width": 2, "hidden": 8, "image_size": [32, 32]},
        MPII_16,
        refiners=[DeepPoseRefiner(16, crop=16, patch=8, width=2)],
    )
    out["cloud"] = save_cloud_model(
        d / "cloud.pt", build_cloud_model("pointnet", 2, width=0.125, seed=0), ["a", "b"]
    )
    return out


LOADERS = {
    "detector": load_detector,
    "segmenter": load_segmenter,
    "pose": load_pose_model,
    "deeppose": load_pose_model,
    "cloud": load_cloud_model,
}


def _mutated(src, dst, change):
    state = torch.load(src, weights_only=True)
    change(state)
    torch.save(state, dst)
    return dst


def _first_float(weights):
    return next(k for k, v in weights.items() if v.is_floating_point() and v.numel() > 1)


# ----------------------------------------------------------------------------- R40
@pytest.mark.parametrize("family", sorted(LOADERS))
def test_each_family_loads_its_own_file(files, family):
    model, info = LOADERS[family](files[family])
    assert not model.training and info["classes"]


@pytest.mark.parametrize("family", sorted(LOADERS))
@pytest.mark.parametrize("damage", ["missing", "extra", "reshaped"])
def test_weights_that_do_not_fit_name_the_file_and_tensor(files, tmp_path, family, damage):
    def change(state):
        w = state["model"]
        name = _first_float(w)
        if damage == "missing":
            del w[name]
        elif damage == "extra":
            w["not.a.layer"] = torch.zeros(3)
        else:
            w[name] = torch.zeros(*w[name].shape[:-1], w[name].shape[-1] + 1)

    p = _mutated(files[family], tmp_path / "bad.pt", change)
    with pytest.raises(FileFormatError, match="not of this model") as err:
        LOADERS[family](p)
    msg = str(err.value)
    assert str(p) in msg and "first '" in msg


def test_a_checkpoint_of_another_kind_is_refused(files, tmp_path):
    # a segmenter's weights under a detector's kind, and the other way round
    p = _mutated(
        files["segmenter"],
        tmp_path / "a.pt",
        lambda s: s.update(kind="fcos", settings={"width": 4}),
    )
    with pytest.raises(FileFormatError, match="not of this model"):
        load_detector(p)
    with pytest.raises(FileFormatError, match="not a segmenter checkpoint"):
        load_segmenter(files["detector"])
    with pytest.raises(FileFormatError, match="not a pose network checkpoint"):
        load_pose_model(files["cloud"])


@pytest.mark.parametrize("entry", [[1, 2], "weights", None, {"a": 1}, {3: torch.zeros(1)}])
def test_a_model_entry_that_is_not_named_tensors(files, tmp_path, entry):
    p = _mutated(files["detector"], tmp_path / "m.pt", lambda s: s.update(model=entry))
    with pytest.raises(FileFormatError, match="named tensors"):
        load_detector(p)
    with pytest.raises(FileFormatError, match="named tensors"):
        load_checkpoint(p, build_detector("fcos", 2, width=4))


def test_a_model_entry_that_is_a_tensor(files, tmp_path):
    p = _mutated(files["cloud"], tmp_path / "m.pt", lambda s: s.update(model=torch.zeros(3)))
    with pytest.raises(FileFormatError, match="named tensors"):
        load_cloud_model(p)


def test_an_integer_tensor_where_the_model_has_floats(files, tmp_path):
    def change(state):
        name = _first_float(state["model"])
        state["model"][name] = state["model"][name].long()

    p = _mutated(files["segmenter"], tmp_path / "i.pt", change)
    with pytest.raises(FileFormatError, match="int64"):
        load_segmenter(p)


@pytest.mark.parametrize("how", ["meta", "sparse"])
def test_tensors_without_dense_values_are_refused(tmp_path, how):
    w = {
        k: v.to("meta") if how == "meta" else v.to_sparse()
        for k, v in nn.Linear(3, 2).state_dict().items()
    }
    p = save_checkpoint(tmp_path / "c.pt", {"model": w})
    with pytest.raises(FileFormatError, match="first 'bias'"):
        load_checkpoint(p, nn.Linear(3, 2))


def test_load_checkpoint_with_a_model_names_the_first_tensor(tmp_path):
    p = save_checkpoint(tmp_path / "c.pt", {"model": nn.Linear(3, 2).state_dict()})
    with pytest.raises(FileFormatError, match=r"first 'weight': shape \(2, 3\)"):
        load_checkpoint(p, nn.Linear(4, 2))


def test_check_state_dict_accepts_the_model_s_own_weights():
    net = nn.Sequential(nn.Conv2d(1, 2, 3), nn.BatchNorm2d(2))
    check_state_dict(net, net.state_dict(), "x.pt")
    with pytest.raises(InputError, match=r"torch\.nn\.Module"):
        check_state_dict("net", {}, "x.pt")


# ----------------------------------------------------------------------------- R41
@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ([4], "not a dict"),
        ("width=4", "not a dict"),
        ({"width": 4, "colour": "red"}, "unknown setting 'colour'"),
        ({"num_classes": 3}, "repeats an argument"),
        ({1: 4}, "keyword arguments"),
        ({"width": torch.tensor(4)}, "not a plain value"),
        ({"width": "x" * 5000}, "not a plain value"),
        ({"strides": [[[8]]]}, "not a plain value"),
        ({"width": 2**40}, "cannot build"),
        ({"width": "four"}, "cannot build"),
    ],
)
def test_damaged_detector_settings(files, tmp_path, settings, match):
    p = _mutated(files["detector"], tmp_path / "s.pt", lambda s: s.update(settings=settings))
    with pytest.raises(FileFormatError, match=match) as err:
        load_detector(p)
    assert str(p) in str(err.value)


def test_settings_follow_the_base_class_signature(files, tmp_path):
    # Mask R-CNN takes the Faster R-CNN settings through **settings: they are allowed
    net = build_detector("maskrcnn", 2, width=4, hidden=16, mask_channels=4, mask_convs=1)
    s = {"width": 4, "hidden": 16, "mask_channels": 4, "mask_convs": 1}
    p = save_detector(tmp_path / "m.pt", net, "maskrcnn", s, ["a", "b"])
    assert type(load_detector(p)[0]).__name__ == "MaskRCNN"
    bad = _mutated(p, tmp_path / "b.pt", lambda st: st["settings"].update(bogus=1))
    with pytest.raises(FileFormatError, match="unknown setting 'bogus'"):
        load_detector(bad)


def test_an_fcn_variant_in_the_settings_is_refused(tmp_path):
    net = build_segmenter("fcn8s", 3, width=4)
    p = save_segmenter(tmp_path / "f.pt", net, "fcn8s", {"width": 4, "variant": "32s"}, ["a", "b"])
    with pytest.raises(FileFormatError, match="variant"):
        load_segmenter(p)
    with pytest.raises(InputError, match="variant"):
        build_segmenter("fcn8s", 3, variant="32s")


@pytest.mark.parametrize(
    ("classes", "match"),
    [
        ([1, 2], r"classes\[0\]"),
        (["a", None], r"classes\[1\]"),
        (["a", "x" * 5000], r"classes\[1\]"),
        ([], "not a list of class names"),
        ("ab", "not a list of class names"),
        (["c"] * (ckpt.MAX_CLASSES + 1), "over the limit"),
    ],
)
def test_damaged_classes(files, tmp_path, classes, match):
    p = _mutated(files["segmenter"], tmp_path / "c.pt", lambda s: s.update(classes=classes))
    with pytest.raises(FileFormatError, match=match):
        load_segmenter(p)


@pytest.mark.parametrize("kind", [["fcos"], 3, None, "resnet"])
def test_damaged_kind(files, tmp_path, kind):
    p = _mutated(files["detector"], tmp_path / "k.pt", lambda s: s.update(kind=kind))
    with pytest.raises(FileFormatError, match="not a detector checkpoint"):
        load_detector(p)


def test_cloud_names_and_point_count_are_checked(files, tmp_path):
    for change, match in [
        (lambda s: s.update(class_names="ab"), "class_names"),
        (lambda s: s.update(class_names=["a", "b", "c"]), "class_names"),
        (lambda s: s.update(part_names=[1]), "part_names"),
        (lambda s: s.update(part_names=["p"], part_classes=[7]), "part_classes"),
        (lambda s: s.update(n_points="1024"), "n_points"),
        (lambda s: s.update(n_points=2**40), "n_points"),
    ]:
        p = _mutated(files["cloud"], tmp_path / "c.pt", change)
        with pytest.raises(FileFormatError, match=match):
            load_cloud_model(p)


# ----------------------------------------------------------------------------- R47
@pytest.mark.parametrize(
    ("family", "settings"),
    [
        ("pose", {"width": 2, "blocks": 2**31}),
        ("pose", {"width": 2**31}),
        ("pose", {"width": 2, "heatmap": "mse", "in_channels": 2**40}),
        ("segmenter", {"width": 4, "depth": 2**31}),
        ("segmenter", {"width": 4096, "depth": 256}),
        ("cloud", {"task": "classify", "width": 1e300}),
    ],
)
def test_absurd_integer_settings_are_refused_at_once(files, tmp_path, family, settings):
    p = _mutated(files[family], tmp_path / "h.pt", lambda s: s.update(settings=settings))
    t0 = time.perf_counter()
    with pytest.raises(FileFormatError) as err:
        LOADERS[family](p)
    assert time.perf_counter() - t0 < 5 and str(p) in str(err.value)


def test_hrnet_blocks_two_to_the_31_does_not_hang(tmp_path):
    net = HRNet(16, width=2, blocks=1, modules=(1, 1))
    p = save_pose_model(
        tmp_path / "h.pt", net, "hrnet", {"width": 2, "blocks": 1, "modules": [1, 1]}, MPII_16
    )
    for settings in (
        {"width": 2, "blocks": 2**31},
        {"width": 2, "blocks": 1, "modules": [2**31, 2**31]},
        {"width": 2, "blocks": 64, "modules": [64, 64]},
        {"width": 2, "modules": 1},
    ):
        bad = _mutated(p, tmp_path / "b.pt", lambda s, v=settings: s.update(settings=v))
        t0 = time.perf_counter()
        with pytest.raises(FileFormatError, match="cannot build"):
            load_pose_model(bad)
        assert time.perf_counter() - t0 < 5


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: HRNet(16, blocks=2**31), "blocks must be at most"),
        (lambda: HRNet(16, blocks=64, modules=(64, 64)), "residual blocks"),
        (lambda: HRNet(16, modules=1), "modules must be two counts"),
        (lambda: HRNet(16, modules=(1, 2, 3)), "modules must be two counts"),
        (lambda: SimpleBaseline(16, width=2**31), "width must be at most"),
        (lambda: DeepPose(16, hidden=2**31), "hidden must be at most"),
        (lambda: DeepPose(16, image_size=(4096, 4096), width=512, hidden=4096), "regressor"),
        (lambda: DeepPoseRefiner(16, patch=2**31), "patch must be at most"),
        (lambda: DeepPoseRefiner(16, width=2**40), "width must be at most"),
        (lambda: NaiveFCN(2, width=4096, depth=256), "NaiveFCN"),
        (lambda: UNet(2, width=64, depth=6), "UNet"),
        (lambda: build_pose_model("hrnet", 16, seed=2**70), "seed must be at most"),
        (lambda: build_detector("fcos", 2, seed=2**70), "seed must be at most"),
    ],
)
def test_constructors_refuse_absurd_sizes(build, match):
    with pytest.raises(InputError, match=match):
        build()


def test_settings_never_build_at_full_size_before_the_weights_fit(files, tmp_path):
    """A file whose settings ask for a large network (each value in range) is refused
    after a build on the meta device only: nothing is allocated from its settings."""
    p = _mutated(
        files["segmenter"],
        tmp_path / "big.pt",
        lambda s: s.update(settings={"width": 128, "depth": 3}),
    )
    devices = []

    def build(kind, n, **settings):
        devices.append(torch.empty(0).device.type)
        return build_segmenter(kind, n + 1, **settings)

    with pytest.raises(FileFormatError, match="not of this model"):
        load_built_model(
            p, SEGMENTERS, build, "segmenter", "save_segmenter", constructors={"unet": UNet}
        )
    assert devices == ["meta"]
    # a file that fits is built once on the meta device, then once for real
    devices.clear()
    load_built_model(files["segmenter"], SEGMENTERS, build, "segmenter", "save_segmenter")
    assert devices == ["meta", "cpu"]


# ----------------------------------------------------------------------------- R45
@pytest.mark.parametrize("family", sorted(LOADERS))
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_non_finite_weights_are_refused(files, tmp_path, family, value):
    def change(state):
        name = _first_float(state["model"])
        state["model"][name] = state["model"][name].clone().fill_(value)

    p = _mutated(files[family], tmp_path / "n.pt", change)
    with pytest.raises(FileFormatError, match="NaN or infinite") as err:
        LOADERS[family](p)
    assert str(p) in str(err.value)


def test_non_finite_weights_in_load_checkpoint_with_a_model(tmp_path):
    w = nn.Linear(3, 2).state_dict()
    w["bias"][0] = math.nan
    p = save_checkpoint(tmp_path / "c.pt", {"model": w})
    with pytest.raises(FileFormatError, match="'bias' holds NaN"):
        load_checkpoint(p, nn.Linear(3, 2))


def test_negative_batch_norm_variance_is_refused(files, tmp_path):
    def change(state):
        name = next(k for k in state["model"] if k.endswith("running_var"))
        state["model"][name] = -state["model"][name].abs() - 1

    p = _mutated(files["segmenter"], tmp_path / "v.pt", change)
    with pytest.raises(FileFormatError, match="negative variances"):
        load_segmenter(p)


def test_damaged_deeppose_stages(files, tmp_path):
    def nan_stage(state):
        st = state["refiners"][0]["state"]
        st[_first_float(st)] = st[_first_float(st)].clone().fill_(math.nan)

    cases = [
        (nan_stage, "refiners\\[0\\].*NaN"),
        (lambda s: s["refiners"][0]["state"].popitem(), "refiners\\[0\\].*not of this model"),
        (lambda s: s["refiners"][0]["settings"].update(width=2**40), "refiners\\[0\\] has bad"),
        (lambda s: s["refiners"][0]["settings"].update(depth=3), "refiners\\[0\\] must be"),
        (lambda s: s.update(refiners=[{"settings": {}, "state": {}}] * 17), "at most 16"),
        (lambda s: s.update(refiners="stage"), "refiners"),
        (lambda s: s.update(skeleton=5), "skeleton"),
        (lambda s: s.update(skeleton={"joints": ["a"]}), "skeleton has 1 joints"),
    ]
    for change, match in cases:
        p = _mutated(files["deeppose"], tmp_path / "d.pt", change)
        with pytest.raises(FileFormatError, match=match):
            load_pose_model(p)


# ----------------------------------------------------------------------------- R55
def test_a_failed_torch_save_is_a_write_error_and_keeps_the_old_file(tmp_path, monkeypatch):
    p = save_checkpoint(tmp_path / "c.pt", {"model": {}, "epoch": 1})

    def full(obj, f, *a, **k):
        try:
            raise OSError(errno.ENOSPC, "No space left on device")
        except OSError:
            raise RuntimeError(
                "[enforce fail at inline_container.cc:672] . unexpected pos"
            ) from None

    monkeypatch.setattr(ckpt.torch, "save", full)
    with pytest.raises(WriteError, match="no space left on the device") as err:
        save_checkpoint(p, {"model": {}, "epoch": 2})
    assert str(p) in str(err.value) and err.value.errno == errno.ENOSPC
    monkeypatch.undo()
    assert load_checkpoint(p)["epoch"] == 1
    assert sorted(x.name for x in tmp_path.iterdir()) == ["c.pt"]


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs POSIX file-size limits")
def test_a_real_file_size_limit_during_a_checkpoint_write(tmp_path):
    """torch.save really fails (RLIMIT_FSIZE stands in for a full disk: the write gets
    EFBIG): WriteError naming the file, the previous checkpoint intact, no temporary
    file left."""
    import resource

    p = save_checkpoint(tmp_path / "c.pt", {"model": {"w": torch.zeros(10)}, "epoch": 1})
    big = {"model": {"w": torch.zeros(1_000_000)}, "epoch": 2}  # 4 MB
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    try:
        resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, hard))
        with pytest.raises(WriteError, match="no space left on the device") as err:
            save_checkpoint(p, big)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old)
    assert str(p) in str(err.value)
    assert load_checkpoint(p)["epoch"] == 1
    assert sorted(x.name for x in tmp_path.iterdir()) == ["c.pt"]
    assert os.path.getsize(p) < 1 << 20


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("kind", sorted(DETECTORS))
def test_every_detector_kind_round_trips(tmp_path, kind):
    small = {"width": 4}
    net = build_detector(kind, 2, **small)
    p = save_detector(tmp_path / "d.pt", net, kind, small, ["a", "b"])
    again, info = load_detector(p)
    assert type(again) is type(net) and info["kind"] == kind
    for k, v in net.state_dict().items():
        assert torch.equal(again.state_dict()[k], v)


@pytest.mark.parametrize("name", SEGMENTERS)
def test_every_segmenter_round_trips(tmp_path, name):
    settings = {"width": 4} if name.startswith("fcn") else {"width": 4, "depth": 2}
    net = build_segmenter(name, 3, **settings)
    p = save_segmenter(tmp_path / "s.pt", net, name, settings, ["a", "b"])
    assert type(load_segmenter(p)[0]) is type(net)


@pytest.mark.parametrize("kind", ["pointnet", "dgcnn"])
def test_every_cloud_network_round_trips(tmp_path, kind):
    s = {"width": 0.125} if kind == "pointnet" else {"widths": [4, 4], "embedding": 8, "k": 4}
    net = build_cloud_model(kind, 2, seed=0, **s)
    p = save_cloud_model(tmp_path / "c.pt", net, ["a", "b"])
    assert type(load_cloud_model(p)[0]) is type(net)


class _InterruptedFile(io.FileIO):
    """A file whose third write is cut by Ctrl-C (or SIGTERM's exception)."""

    def __init__(self, path, mode, stop):
        super().__init__(path, mode)
        self.writes, self.stop = 0, stop

    def write(self, b):
        self.writes += 1
        if self.writes == 3:
            raise self.stop
        return super().write(b)


@pytest.mark.parametrize("stop", [KeyboardInterrupt, SystemExit])
def test_an_interruption_during_the_write_goes_on_as_itself(tmp_path, monkeypatch, stop):
    """Found by the faults campaign: Ctrl-C while torch.save wrote the checkpoint came out
    as torch's RuntimeError ("unexpected pos"), so `nn pose train` exited 1, not 130."""
    from robopercept.nn.train import checkpoint as ck

    path = tmp_path / "c.pt"
    ck.save_checkpoint(path, {"epoch": 1, "w": torch.zeros(4000)})
    before = path.read_bytes()
    monkeypatch.setattr(ck, "open", lambda p, mode: _InterruptedFile(p, mode, stop), raising=False)
    with pytest.raises(stop):
        ck.save_checkpoint(path, {"epoch": 2, "w": torch.ones(4000)})
    assert path.read_bytes() == before  # the last complete checkpoint stays
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.pt"]  # no temporary left
