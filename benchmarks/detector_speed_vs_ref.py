"""Detector speed against an earlier commit (issue 45: "forward and backward time of each
detector within 5% of before, paired, in one process").

The package of the reference commit is materialized beside the current one in the same
process: ``git archive REF src/robopercept`` is extracted into a temporary folder, the
package folder is renamed ``robopercept_ref`` and every ``robopercept`` module reference
in its ``.py`` files (``from robopercept...`` / ``import robopercept...`` statements,
``files("robopercept")`` and dotted module strings such as ``"robopercept.cli.main"``)
is rewritten to ``robopercept_ref``; its data files come along. Then ``robopercept``
(this checkout's ``src``) and ``robopercept_ref`` are imported side by side.

For each detector kind of ``build_detector`` (fcos, faster, fast, rcnn, localizer,
maskrcnn, keypointrcnn) both packages build the model with the same seed and settings
(``width`` 16 and the other defaults), and run on one fixed batch of 4 images of
128 x 128 (``procedural_detection_set``, or ``procedural_pose_scenes`` for Keypoint
R-CNN; the localizer gets each image's first box). Parity is checked first: state-dict
entries that match one to one (the same keys; else renamed keys in the same order with
the same shapes; else matched by shape, value and gradient) with equal values, the
reference's state dict loading (strict) into a current model and giving the current's
own values, the same train-mode losses and gradients, and the same eval-mode outputs
(also at ``score_thresh`` 0 when nothing passes the default). The table's parity column
says ``same``, ``renamed`` (keys renamed, all else identical) or ``DIFFERS``.

Timing, one torch thread: train mode ``sum(model(images, targets).values()).backward()``
and eval-mode forward (under ``no_grad``), alternating reference and current (AB BA AB ...,
the order flipped every call pair), after a warm-up; torch's generator is re-seeded
before every call so both do the same sampling. Each timed pair is the least of
``--repeats`` alternations of each (the minimum sheds a shared machine's slow-downs).
Reported per detector: the median seconds of each, the median of the per-pair ratios
current / ref with their 10-90 % spread, the ratio of the overall minima, and whether
the median train ratio is within 1.05. Writes
benchmarks/results/detector_speed_vs_ref.json.

Run from the repository root::

    .venv/bin/python -m benchmarks.detector_speed_vs_ref --ref c5bf220 [--pairs 15]
        [--repeats 3] [--eval-pairs 10] [--eval-repeats 2] [--kinds fcos faster ...]
"""

from __future__ import annotations

import argparse
import importlib
import io
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results" / "detector_speed_vs_ref.json"
KINDS = ("fcos", "faster", "fast", "rcnn", "localizer", "maskrcnn", "keypointrcnn")
REF_NAME = "robopercept_ref"
TARGET = 1.05

# module references to rewrite in the reference package's .py files
_REWRITES = (
    (re.compile(r"^(\s*from\s+)robopercept(?=[.\s])", re.M), rf"\1{REF_NAME}"),
    (re.compile(r"^(\s*import\s+)robopercept(?=[.\s,]|$)", re.M), rf"\1{REF_NAME}"),
    (re.compile(r"""files\((["'])robopercept\1\)"""), rf'files("{REF_NAME}")'),
    # dotted module strings for importlib: "robopercept.cli.main" (lower-case parts only)
    (
        re.compile(r"""(["'])robopercept((?:\.[a-z_][a-z0-9_]*)+)\1"""),
        rf"\1{REF_NAME}\2\1",
    ),
)


def materialize(ref: str, dest: Path) -> tuple[str, int]:
    """Extract ``src/robopercept`` of ``ref`` into ``dest/robopercept_ref`` with its module
    references rewritten; returns the full commit id and the number of rewritten lines."""
    commit = subprocess.run(
        ["git", "rev-parse", "--verify", f"{ref}^{{commit}}"],
        cwd=ROOT, check=True, capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip
    blob = subprocess.run(
        ["git", "archive", commit, "src/robopercept"], cwd=ROOT, check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(blob)) as tar:
        tar.extractall(dest / "_archive", filter="data")
    shutil.move(dest / "_archive" / "src" / "robopercept", dest / REF_NAME)
    shutil.rmtree(dest / "_archive")
    changed = 0
    for py in (dest / REF_NAME).rglob("*.py"):
        text = py.read_text(encoding="utf-8")
        new = text
        for pattern, repl in _REWRITES:
            new = pattern.sub(repl, new)
        if new != text:
            changed += sum(a != b for a, b in zip(text.splitlines(), new.splitlines(), strict=True))
            py.write_text(new, encoding="utf-8")
    return commit, changed


def _find(pkg: str, name: str, candidates: tuple[str, ...]) -> Any:
    """``name`` from the first of ``pkg.<candidate>`` modules that has it."""
    for mod in candidates:
        try:
            m = importlib.import_module(f"{pkg}.{mod}")
        except ImportError:
            continue
        if hasattr(m, name):
            return getattr(m, name)
    raise ImportError(f"{name} not found in {pkg}.{{{', '.join(candidates)}}}")


def build_detector_of(pkg: str) -> Any:
    """``build_detector`` of package ``pkg`` (flat ``nn.detection`` at old commits,
    ``nn.detection.zoo`` after issue 45)."""
    return _find(pkg, "build_detector", ("nn.detection.zoo", "nn.detection", "nn.zoo"))


def make_batches(
    n: int, size: int, seed: int
) -> tuple[dict[str, tuple[list[Any], list[Any]]], int, int]:
    """Fixed inputs per kind (float images in [0, 1] and their targets, from the current
    package's procedural sets), the number of shape classes and of pose classes."""
    import torch

    from robopercept.nn.detection.synthetic import procedural_detection_set
    from robopercept.nn.pose.data import procedural_pose_scenes

    def convert(ds: Any, keep: tuple[str, ...]) -> tuple[list[Any], list[Any]]:
        images, targets = [], []
        for i in range(len(ds)):
            im, t = ds[i]
            images.append(im.to(torch.float32) / 255.0)
            targets.append({k: v for k, v in t.items() if k in keep})
        return images, targets

    det = procedural_detection_set(n, (size, size), rng=seed)
    pose = procedural_pose_scenes(n, (size, size), rng=seed, people=(1, 3))
    boxes = convert(det, ("boxes", "labels"))
    single = (boxes[0], [{k: v[:1] for k, v in t.items()} for t in boxes[1]])
    out = {k: boxes for k in ("fcos", "faster", "fast", "rcnn")}
    out["localizer"] = single
    out["maskrcnn"] = convert(det, ("boxes", "labels", "masks"))
    out["keypointrcnn"] = convert(pose, ("boxes", "labels", "keypoints"))
    return out, len(det.classes), len(pose.classes)


def settings_of(kind: str, n_classes: int, n_person: int) -> tuple[int, dict[str, Any]]:
    """``num_classes`` and keyword settings (defaults but ``width=16``) of ``kind``."""
    if kind == "keypointrcnn":
        return n_person, {"width": 16, "num_keypoints": 16}
    return n_classes, {"width": 16}


def _flat(x: Any) -> list[Any]:
    """Tensors of nested outputs, in order (dict keys sorted)."""
    import torch

    if isinstance(x, torch.Tensor):
        return [x]
    if isinstance(x, dict):
        return [t for k in sorted(x) for t in _flat(x[k])]
    if isinstance(x, (list, tuple)):
        return [t for v in x for t in _flat(v)]
    return []


def _max_diff(a: list[Any], b: list[Any]) -> float | None:
    """Largest absolute difference, or None when the lists differ in length or shapes."""
    if len(a) != len(b) or any(x.shape != y.shape for x, y in zip(a, b, strict=True)):
        return None
    d = 0.0
    for x, y in zip(a, b, strict=True):
        if x.numel():
            d = max(d, float((x.double() - y.double()).abs().max()))
    return d


def _train_step(model: Any, images: list[Any], targets: list[Any], seed: int) -> Any:
    import torch

    model.zero_grad(set_to_none=True)
    torch.manual_seed(seed)
    losses = model(images, targets)
    sum(losses.values()).backward()
    return losses


def _eval_step(model: Any, images: list[Any], seed: int) -> Any:
    import torch

    torch.manual_seed(seed)
    with torch.no_grad():
        return model(images)


def _detached(sd: Any) -> dict[str, Any]:
    return {k: v.detach().clone() for k, v in sd.items()}


def key_map(
    sr: dict[str, Any], sc: dict[str, Any], gr: dict[str, Any], gc: dict[str, Any]
) -> tuple[dict[str, str], str]:
    """State-dict keys of ``sr`` (reference) matched to those of ``sc`` (current): the same
    keys, else the same shapes in order, else by content (the same shape, values and
    gradient ``gr``/``gc``, the same name or the first in order preferred). Returns the
    match (unmatched keys left out) and how it was made."""
    import torch

    if list(sr) == list(sc):
        return {k: k for k in sr}, "same"
    if len(sr) == len(sc) and all(sr[a].shape == sc[b].shape for a, b in zip(sr, sc, strict=True)):
        return dict(zip(sr, sc, strict=True)), "renamed, same order"
    left = list(sc)
    match = {}

    def same(a: str, b: str) -> bool:
        if sr[a].shape != sc[b].shape or not torch.equal(sr[a], sc[b]):
            return False
        ga, gb = gr.get(a), gc.get(b)
        return (ga is None and gb is None) or (
            ga is not None and gb is not None and torch.equal(ga, gb)
        )

    for a in sr:
        found = [b for b in left if same(a, b)]
        if found:
            b = a if a in found else found[0]
            match[a] = b
            left.remove(b)
    return match, "renamed, matched by shape, values and gradients"


def parity(
    ref: Any, cur: Any, fresh_cur: Any, images: list[Any], targets: list[Any], seed: int
) -> dict:
    """Parity of ``ref`` and ``cur`` (built alike): state dicts (values, and loading the
    reference's into ``fresh_cur``), train-mode losses and gradients, eval outputs."""
    import torch

    sr, sc = _detached(ref.state_dict()), _detached(cur.state_dict())
    try:
        fresh_cur.load_state_dict(dict(sr), strict=True)
        sl = fresh_cur.state_dict()
        loads = list(sl) == list(sc) and all(torch.equal(sl[k], sc[k]) for k in sc)
        loads_note = "loads, equals current's own" if loads else "loads, DIFFERS"
    except Exception as exc:
        loads, loads_note = False, f"does not load: {type(exc).__name__}: {str(exc)[:300]}"
    ref.train(), cur.train()
    lr = _train_step(ref, images, targets, seed)
    lc = _train_step(cur, images, targets, seed)
    lr = {k: v.detach() for k, v in lr.items()}
    lc = {k: v.detach() for k, v in lc.items()}
    losses = {k: [float(lr[k]) if k in lr else None, float(lc[k]) if k in lc else None]
              for k in {**lr, **lc}}  # fmt: skip
    loss_diff = (
        _max_diff([lr[k] for k in sorted(lr)], [lc[k] for k in sorted(lc)])
        if sorted(lr) == sorted(lc)
        else None
    )
    gr = {k: p.grad for k, p in ref.named_parameters() if p.grad is not None}
    gc = {k: p.grad for k, p in cur.named_parameters() if p.grad is not None}
    match, how = key_map(sr, sc, gr, gc)
    only_ref = [k for k in sr if k not in match]
    only_cur = sorted(set(sc) - set(match.values()))
    values = _max_diff([sr[a] for a in match], [sc[b] for b in match.values()])
    pairs = [(a, b) for a, b in match.items() if a in gr or b in gc]
    grads_complete = all(a in gr and b in gc for a, b in pairs) and len(pairs) == len(gr) == len(gc)
    grad_diff = (
        _max_diff([gr[a] for a, _ in pairs], [gc[b] for _, b in pairs]) if grads_complete else None
    )
    ref.eval(), cur.eval()
    er, ec = _eval_step(ref, images, seed), _eval_step(cur, images, seed)
    thresh = None
    if all(len(d["boxes"]) == 0 for d in er) and hasattr(ref, "score_thresh"):
        # nothing above the default threshold: compare the outputs at threshold 0 too
        thresh = (ref.score_thresh, cur.score_thresh)
        ref.score_thresh = cur.score_thresh = 0.0
        er0, ec0 = _eval_step(ref, images, seed), _eval_step(cur, images, seed)
        ref.score_thresh, cur.score_thresh = thresh
        er, ec = er + er0, ec + ec0
    out_keys = [sorted(d) for d in er] == [sorted(d) for d in ec]
    eval_diff = _max_diff(_flat(er), _flat(ec)) if out_keys else None
    ok = (
        not only_ref
        and not only_cur
        and values == 0.0
        and loads
        and loss_diff == 0.0
        and grad_diff == 0.0
        and eval_diff == 0.0
    )
    return {
        "identical": ok,
        "state_dict_keys": how,
        "state_dict_renamed": {a: b for a, b in match.items() if a != b},
        "state_dict_unmatched_ref": only_ref,
        "state_dict_unmatched_current": only_cur,
        "state_dict_max_abs_diff": values,
        "ref_state_dict_into_current": loads_note,
        "losses_ref_current": losses,
        "loss_max_abs_diff": loss_diff,
        "grad_max_abs_diff": grad_diff,
        "eval_detections_ref_current": [
            [int(d["boxes"].shape[0]) for d in er],
            [int(d["boxes"].shape[0]) for d in ec],
        ],
        "eval_also_at_score_thresh_0": thresh is not None,
        "eval_max_abs_diff": eval_diff,
    }


def _q(values: list[float], q: float) -> float:
    s = sorted(values)
    pos = q * (len(s) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


def paired(ref_fn: Any, cur_fn: Any, pairs: int, repeats: int, warmup: int) -> dict[str, Any]:
    """Seconds of ``ref_fn`` and ``cur_fn`` alternated, the order flipped every call pair;
    each of the ``pairs`` samples is the least of ``repeats`` such alternations (the
    minimum sheds the slow-downs of a shared machine)."""
    for _ in range(warmup):
        ref_fn(), cur_fn()
    t_ref: list[float] = []
    t_cur: list[float] = []
    flip = False
    for _ in range(pairs):
        block: dict[int, list[float]] = {0: [], 1: []}
        for _ in range(repeats):
            order = ((ref_fn, 0), (cur_fn, 1))
            for fn, side in order[::-1] if flip else order:
                t0 = time.perf_counter()
                fn()
                block[side].append(time.perf_counter() - t0)
            flip = not flip
        t_ref.append(min(block[0]))
        t_cur.append(min(block[1]))
    ratios = [c / r for c, r in zip(t_cur, t_ref, strict=True)]
    return {
        "ref_median_s": statistics.median(t_ref),
        "current_median_s": statistics.median(t_cur),
        "ratio_median": statistics.median(ratios),
        "ref_min_s": min(t_ref),
        "current_min_s": min(t_cur),
        "ratio_of_minima": min(t_cur) / min(t_ref),
        "ratio_p10": _q(ratios, 0.1),
        "ratio_p90": _q(ratios, 0.9),
        "ratio_min": min(ratios),
        "ratio_max": max(ratios),
        "ref_s": t_ref,
        "current_s": t_cur,
    }


_HEADER = (
    f"{'train ref ms':>12} {'cur ms':>7} {'ratio':>6} {'p10-p90':>11} {'min/min':>7} "
    f"{'<=1.05':>6} | {'eval ref ms':>11} {'cur ms':>7} {'ratio':>6} {'p10-p90':>11}"
)


def _parity_word(par: dict) -> str:
    if not par["identical"]:
        return "DIFFERS"
    return "same" if par["state_dict_keys"] == "same" else "renamed"


def _line(row: dict) -> str:
    """One table row's figures (see ``_HEADER``)."""
    t, e = row["train_fwd_bwd"], row["eval_fwd"]
    return (
        f"{t['ref_median_s'] * 1e3:>12.1f} {t['current_median_s'] * 1e3:>7.1f} "
        f"{t['ratio_median']:>6.3f} {t['ratio_p10']:>5.3f}-{t['ratio_p90']:<5.3f} "
        f"{t['ratio_of_minima']:>7.3f} {'yes' if row['within_5_percent'] else 'NO':>6} | "
        f"{e['ref_median_s'] * 1e3:>11.1f} {e['current_median_s'] * 1e3:>7.1f} "
        f"{e['ratio_median']:>6.3f} {e['ratio_p10']:>5.3f}-{e['ratio_p90']:<5.3f}"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref", default="c5bf220", help="reference commit (git rev)")
    ap.add_argument("--pairs", type=int, default=15, help="timed ABAB pairs per detector")
    ap.add_argument("--repeats", type=int, default=3, help="alternations per timed pair")
    ap.add_argument("--warmup", type=int, default=2, help="untimed pairs first")
    ap.add_argument("--eval-pairs", type=int, default=10)
    ap.add_argument("--eval-repeats", type=int, default=2)
    ap.add_argument("--kinds", nargs="*", default=list(KINDS), choices=KINDS)
    ap.add_argument("--images", type=int, default=4)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS)
    a = ap.parse_args(argv)
    eval_pairs = a.eval_pairs

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)
    load0 = list(os.getloadavg())
    tmp = Path(tempfile.mkdtemp(prefix="robopercept_ref_"))
    try:
        commit, rewritten = materialize(a.ref, tmp)
        sys.path.insert(0, str(tmp))
        if str(ROOT / "src") not in sys.path:
            sys.path.insert(0, str(ROOT / "src"))
        import robopercept

        importlib.import_module(REF_NAME)
        assert Path(robopercept.__file__).resolve().is_relative_to(ROOT / "src"), robopercept
        build_ref, build_cur = build_detector_of(REF_NAME), build_detector_of("robopercept")
        print(f"ref {a.ref} = {commit[:12]}: {REF_NAME} from {tmp} ({rewritten} lines rewritten)")
        print(f"  ref build_detector: {build_ref.__module__}; current: {build_cur.__module__}")
        batches, n_classes, n_person = make_batches(a.images, a.size, a.seed)
        rows = []
        for kind in a.kinds:
            images, targets = batches[kind]
            k, settings = settings_of(kind, n_classes, n_person)
            ref = build_ref(kind, k, seed=a.seed, **settings)
            cur = build_cur(kind, k, seed=a.seed, **settings)
            fresh = build_cur(kind, k, seed=a.seed + 1, **settings)
            par = parity(ref, cur, fresh, images, targets, a.seed)
            del fresh
            print(f"{kind:<13} parity: {_parity_word(par)}")
            if not par["identical"]:
                shown = {k: v for k, v in par.items() if v not in ([], {})}
                print("  " + json.dumps(shown, default=str)[:3000])
            else:
                print(f"  state dict keys {par['state_dict_keys']}; the ref's state dict "
                      f"{par['ref_state_dict_into_current']}")  # fmt: skip
            ref.train(), cur.train()
            train = paired(
                lambda: _train_step(ref, images, targets, a.seed),  # noqa: B023
                lambda: _train_step(cur, images, targets, a.seed),  # noqa: B023
                a.pairs,
                a.repeats,
                a.warmup,
            )
            ref.eval(), cur.eval()
            evals = paired(
                lambda: _eval_step(ref, images, a.seed),  # noqa: B023
                lambda: _eval_step(cur, images, a.seed),  # noqa: B023
                eval_pairs,
                a.eval_repeats,
                a.warmup,
            )
            row = {
                "kind": kind,
                "model": type(cur).__name__,
                "num_classes": k,
                "settings": settings,
                "parity": par,
                "train_fwd_bwd": train,
                "eval_fwd": evals,
                "within_5_percent": train["ratio_median"] <= TARGET,
            }
            rows.append(row)
            print("  " + _line(row), flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    print(f"\n{'detector':<13} {'parity':<8} " + _HEADER)
    for r in rows:
        print(f"{r['kind']:<13} {_parity_word(r['parity']):<8} " + _line(r))
    out = {
        "benchmark": "detector_speed_vs_ref",
        "ref": a.ref,
        "ref_commit": commit,
        "current": subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
        + " + working tree",
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "cpus": os.cpu_count(),
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "images": a.images,
        "size": [a.size, a.size],
        "seed": a.seed,
        "pairs": a.pairs,
        "repeats": a.repeats,
        "eval_pairs": eval_pairs,
        "eval_repeats": a.eval_repeats,
        "warmup_pairs": a.warmup,
        "target_ratio": TARGET,
        "load_average_before_after": [load0, list(os.getloadavg())],
        "detectors": rows,
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(out, indent=2) + "\n")
    print(f"-> {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
