"""``robopercept nn detect train|eval|IMAGE...`` (issue 26, item 6): tiny runs (a few
64 x 64 digit canvases, a few epochs) so the file runs in well under a minute."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.cli.nn import detect as cli_detect  # noqa: E402
from robopercept.imaging import read_image, write_image  # noqa: E402
from robopercept.nn.coco.dataset import write_coco_json  # noqa: E402
from robopercept.nn.coco.results import read_coco_results  # noqa: E402
from robopercept.nn.detection.synthetic import digits_detection_set  # noqa: E402
from robopercept.nn.detection.train import evaluate_detector  # noqa: E402
from robopercept.nn.detection.zoo import load_detector  # noqa: E402
from tests.cli.nn_runs import check_run_folder_rules  # noqa: E402

DATA = ["--data", "digits", "--images", "8", "--size", "64x64", "--seed", "0"]
TRAIN = ["nn", "detect", "train", *DATA, "--model", "fcos", "--width", "8"]
TRAIN += ["--lr", "3e-3", "--batch-size", "4", "--quiet"]
FILES = {"model.pt", "history.json", "metrics.json", "pr_curves.png", "samples.png"}


pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, dict]:
    """6 epochs of a width-8 FCOS on 6 training canvases (about 5 s): enough for
    non-zero validation metrics, so the equality checks below can fail."""
    out = tmp_path_factory.mktemp("det") / "run"
    torch.set_num_threads(1)
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*TRAIN, "--epochs", "6", "--json", "-o", str(out)]) == 0
    return out, json.loads(buf.getvalue())


def _val():
    # the CLI's split of --images 8 --size 64x64 --seed 0: 80 / 20 with the seed
    ds = digits_detection_set(8, (64, 64), rng=0)
    return ds.split((0.8, 0.2), rng=0)[1]


def test_train_writes_the_run_folder(run):
    out, printed = run
    assert FILES <= {p.name for p in out.iterdir()}
    assert set(printed) >= {"metrics", "stats", "files", "epochs", "images", "model"}
    assert printed["epochs"] == 6 and printed["images"] == 2
    names = ["AP", "AP50", "AP75", "APs", "APm", "APl"]
    names += ["AR1", "AR10", "AR100", "ARs", "ARm", "ARl"]
    assert list(printed["metrics"]) == names
    assert json.loads((out / "metrics.json").read_text())["stats"] == printed["stats"]
    hist = json.loads((out / "history.json").read_text())
    assert len(hist["losses"]) == 6 and len(hist["seconds"]) == 6
    assert hist["losses"][-1]["loss"] < hist["losses"][0]["loss"]
    # --val-every defaults to epochs / 10 (here every epoch); the kept epoch has the
    # best validation AP, and the printed metrics are that epoch's
    val = {int(k): v for k, v in hist["val_AP"].items()}
    assert sorted(val) == [1, 2, 3, 4, 5, 6]
    assert hist["best_epoch"] == printed["best_epoch"] == max(val, key=lambda e: (val[e], -e))
    assert printed["stats"][0] == pytest.approx(val[hist["best_epoch"]], abs=1e-12)
    assert read_image(out / "pr_curves.png").shape[:2] == (1000, 1600)
    # two 64 x 64 validation images side by side, each enlarged 12 times to 768 (issue
    # 48: read at 1080p), 8 px apart, under the legend and their titles
    samples = read_image(out / "samples.png")
    assert samples.shape[1] == 2 * 768 + 8 and 768 < samples.shape[0] < 900


def test_metrics_equal_evaluate_detector_on_saved_model(run, capsys):
    out, printed = run
    model, info = load_detector(out / "model.pt")
    assert info["kind"] == "fcos" and info["settings"] == {"width": 8}
    assert info["classes"] == [str(d) for d in range(10)]
    ev = evaluate_detector(model, _val())
    assert ev.stats[1] > 0  # a trained model: the comparisons below are not of zeros
    assert printed["stats"] == ev.stats.tolist()
    # eval of the run folder gives the same 12 numbers
    assert main(["nn", "detect", "eval", str(out), *DATA, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["stats"] == ev.stats.tolist()


def test_tta_flag_equals_the_wrapper_in_eval_and_detect(run, tmp_path, capsys):
    from robopercept.nn.detection.tta import TestTimeAugmentation
    from robopercept.nn.detection.zoo import detect_arrays

    out, _ = run
    model, _ = load_detector(out / "model.pt")
    tta = TestTimeAugmentation(model, "hflip")
    assert main(["nn", "detect", "eval", str(out), *DATA, "--tta", "hflip", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["tta"] == "hflip"
    assert printed["stats"] == evaluate_detector(tta, _val()).stats.tolist()
    image = (np.asarray(_val().images[0]) * 255).round().astype(np.uint8)
    write_image(tmp_path / "c.png", image)
    argv = ["nn", "detect", str(tmp_path / "c.png"), "--model", str(out), "--tta", "hflip"]
    assert main([*argv, "--json", "--score-thresh", "0.0"]) == 0
    rows = json.loads(capsys.readouterr().out)["results"]
    d = detect_arrays(tta, [image])[0]
    assert len(rows) == len(d["scores"]) > 0
    assert [r["score"] for r in rows] == pytest.approx(d["scores"].tolist(), abs=1e-7)


def test_tta_scales_and_none_reach_the_predictor(run, tmp_path, capsys):
    """--tta identity --tta-scales 0.8 1 equals the wrapper at those scales; --tta none
    equals the bare model; --tta-scales with --tta none is refused naming the flags."""
    from robopercept.nn.detection.tta import TestTimeAugmentation
    from robopercept.nn.detection.zoo import detect_arrays

    out, _ = run
    model, _ = load_detector(out / "model.pt")
    image = (np.asarray(_val().images[1]) * 255).round().astype(np.uint8)
    write_image(tmp_path / "c.png", image)
    argv = ["nn", "detect", str(tmp_path / "c.png"), "--model", str(out), "--json"]
    argv += ["--score-thresh", "0.0"]
    assert main([*argv, "--tta", "identity", "--tta-scales", "0.8", "1"]) == 0
    rows = json.loads(capsys.readouterr().out)["results"]
    d = detect_arrays(TestTimeAugmentation(model, "identity", scales=(0.8, 1.0)), [image])[0]
    assert len(rows) == len(d["scores"]) > 0
    assert [r["score"] for r in rows] == pytest.approx(d["scores"].tolist(), abs=1e-7)
    assert main([*argv, "--tta", "none"]) == 0
    rows = json.loads(capsys.readouterr().out)["results"]
    assert [r["score"] for r in rows] == pytest.approx(
        detect_arrays(model, [image])[0]["scores"].tolist(), abs=1e-7
    )
    assert main([*argv, "--tta", "none", "--tta-scales", "1"]) == 2
    assert "--tta-scales needs test-time augmentation: drop --tta none" in capsys.readouterr().err


def test_eval_writes_metrics_and_curves(run, tmp_path, capsys):
    out, printed = run
    assert main(["nn", "detect", "eval", str(out / "model.pt"), *DATA, "-o", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "AP50" in text and "metrics.json" in text
    assert json.loads((tmp_path / "metrics.json").read_text())["stats"] == printed["stats"]
    assert (tmp_path / "pr_curves.png").is_file()


def test_eval_on_coco_json(run, tmp_path, capsys):
    # the validation canvases as a COCO file with PNG images: same numbers
    out, printed = run
    val = _val()
    coco = val.to_coco()
    for im, rec in zip(val.images, coco.images, strict=True):
        write_image(tmp_path / rec.file_name, (np.asarray(im) * 255).round().astype(np.uint8))
    write_coco_json(coco, tmp_path / "val.json")
    argv = ["nn", "detect", "eval", str(out), "--data", str(tmp_path / "val.json"), "--json"]
    assert main(argv) == 0
    stats = json.loads(capsys.readouterr().out)["stats"]
    assert stats[1] == pytest.approx(printed["stats"][1], abs=0.35)  # uint8 round trip
    assert len(stats) == 12


def test_detect_images_draws_and_prints_coco_results(run, tmp_path, capsys):
    out, _ = run
    val = _val()
    paths = []
    for k in range(2):
        p = tmp_path / f"canvas{k}.png"
        write_image(p, (np.asarray(val.images[k]) * 255).round().astype(np.uint8))
        paths.append(str(p))
    argv = ["nn", "detect", *paths, "--model", str(out / "model.pt"), "-o", str(tmp_path / "o")]
    assert main([*argv, "--json", "--score-thresh", "0.05"]) == 0
    doc = json.loads(capsys.readouterr().out)
    own = "(your own run; its training data is what you gave it)"
    assert doc["model"] == f"model: {out / 'model.pt'} {own}"
    rows = doc["results"]
    assert rows, "a trained model finds something at score 0.05"
    assert {r["image_id"] for r in rows} <= {1, 2}
    assert len(read_coco_results_list(rows, tmp_path)) == len(rows)
    for k in range(2):
        pic = read_image(tmp_path / "o" / f"canvas{k}.png")
        assert pic.shape == (64, 64, 3)


def read_coco_results_list(rows, tmp_path):
    """The printed rows are a valid COCO results file (read back by our reader)."""
    f = tmp_path / "results.json"
    f.write_text(json.dumps(rows))
    return read_coco_results(f)


def test_default_model_missing_names_the_build_command(tmp_path, capsys, monkeypatch):
    from robopercept.nn import shipped

    monkeypatch.setitem(
        shipped.SHIPPED_DETECTORS, shipped.DEFAULT_SHIPPED["detect"], "data/no_such_model.pt"
    )
    img = tmp_path / "a.png"
    write_image(img, np.zeros((32, 32, 3), np.uint8))
    assert main(["nn", "detect", str(img), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    # the card's own command: rebuilds just that model
    build = shipped.MODEL_CARDS[shipped.DEFAULT_SHIPPED["detect"]].build
    assert build in err and "data/no_such_model.pt" in err
    assert "python -m benchmarks.detection_figures --only shapes-fcos-ema" in build
    assert "shapes-fcos-ema shapes-faster" in " ".join(cli_detect.__doc__.split())


@pytest.mark.parametrize(
    ("argv", "flag"),
    [
        (["train", "--data", "foo", "-o", "x"], "--data"),
        (["train", "--data", "missing.json", "-o", "x"], "--data"),
        (["train", "--data", "digits", "--epochs", "0", "-o", "x"], "--epochs"),
        (["train", "--data", "trees", "-o", "x"], "--images-dir"),
        (["train", "--data", "digits", "--model", "yolo"], "--model"),
        (["train", "--data", "digits", "--size", "4x4"], "--size"),
        (["train", "--data", "digits", "--ema", "1.5"], "--ema"),
        (["eval", "run", "--data", "digits", "--tta", "rotations"], "--tta"),
        (["eval", "run", "--data", "foo"], "--data"),
        (["eval", "no_run", "--data", "digits"], "RUN_OR_MODEL"),
        (["a.png", "--model", "no.pt", "-o", "x"], "--model"),
        (["a.png", "--score-thresh", "2"], "--score-thresh"),
        (["nothing.png", "--model", "a.png", "-o", "x"], "IMAGE"),
    ],
)
def test_bad_arguments_exit_2_naming_the_flag(argv, flag, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write_image(tmp_path / "a.png", np.zeros((32, 32, 3), np.uint8))
    assert main(["nn", "detect", *argv]) == 2
    assert flag in capsys.readouterr().err


def test_coco_images_dir_missing_exits_2(tmp_path, capsys):
    f = tmp_path / "c.json"
    f.write_text(json.dumps({"images": [], "categories": [], "annotations": []}))
    argv = ["nn", "detect", "train", "--data", str(f), "--images-dir", str(tmp_path / "no")]
    assert main(argv) == 2
    assert "--images-dir" in capsys.readouterr().err


def test_not_a_detector_checkpoint_fails(tmp_path, capsys):
    bad = tmp_path / "m.pt"
    torch.save({"model": {}}, bad)
    img = tmp_path / "a.png"
    write_image(img, np.zeros((32, 32, 3), np.uint8))
    assert main(["nn", "detect", str(img), "--model", str(bad), "-o", str(tmp_path / "o")]) == 1
    assert "not a detector checkpoint" in capsys.readouterr().err


def test_no_words_prints_help_and_exits_2(capsys):
    assert main(["nn", "detect"]) == 2
    assert "nn detect train" in capsys.readouterr().out


def test_ema_flag_reaches_train_detector(tmp_path, monkeypatch, capsys):
    import robopercept.nn.detection.run as det

    seen = {}
    real = det.train_detector

    def spy(*args, **kwargs):
        seen["ema"] = kwargs.get("ema")
        return real(*args, **kwargs)

    monkeypatch.setattr(det, "train_detector", spy)
    argv = [*TRAIN, "--epochs", "1", "--ema", "0.9", "--json", "-o", str(tmp_path / "r")]
    assert main(argv) == 0
    assert seen == {"ema": 0.9}
    assert json.loads(capsys.readouterr().out)["epochs"] == 1


def test_outputs_over_the_inputs_are_refused(tmp_path, capsys):
    img = tmp_path / "a.png"
    write_image(img, np.zeros((32, 32, 3), np.uint8))
    assert main(["nn", "detect", str(img), "-o", str(tmp_path)]) == 2
    assert "would overwrite the input" in capsys.readouterr().err
    assert read_image(img).max() == 0  # untouched


def test_run_folder_rules(tmp_path, capsys):
    # 2 epochs of a width-4 FCOS on 3 training canvases of 64 x 64 (a few seconds)
    argv = ["nn", "detect", "train", "--data", "digits", "--images", "4", "--size", "64x64"]
    argv += ["--model", "fcos", "--width", "4", "--batch-size", "2", "--epochs", "2"]
    check_run_folder_rules([*argv, "--quiet"], tmp_path, "model.pt", capsys)


def test_resume_and_overwrite_exclude_each_other(tmp_path, capsys):
    argv = ["nn", "detect", "train", "--data", "digits", "--resume", "--overwrite"]
    assert main([*argv, "-o", str(tmp_path / "r")]) == 2
    assert "--resume and --overwrite exclude each other" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_parser_names_are_the_run_modules():
    from robopercept.nn.detection.run import BUILTIN_DATA, RUN_DETECTORS

    assert cli_detect.DETECTOR_NAMES == RUN_DETECTORS
    assert cli_detect.BUILTIN_DATA == BUILTIN_DATA
