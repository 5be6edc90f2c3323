"""Batch jobs: one robopercept job over many inputs, on a Dask distributed cluster.

:func:`run_batch` runs a job (:data:`JOBS`: ``cloud``, ``edges``, ``features``,
``stereo``, ``plane-track`` and the network predictions ``nn-predict``, ``nn-detect``,
``nn-segment``, ``nn-pose``, ``nn-cloud``) on every input, each as one Dask task that
calls :func:`run_item`: the same library code a single-process run uses, writing the
item's files into ``OUT/<item>/``. The scheduler is a :class:`distributed.LocalCluster`
(``scheduler="local"``: ``workers`` processes of one thread each) or an existing
cluster (``scheduler="tcp://HOST:PORT"``, whose workers must see the inputs and ``OUT``
at the same paths: a shared file system).

Tasks are submitted with ``pure=False``. An item that raised is submitted again, up
to ``retries`` more times (its ``attempts`` count them); an item whose worker died is
rescheduled on another worker by Dask itself within the same attempt (up to
``distributed.scheduler.allowed-failures`` times, then it fails with
``KilledWorker`` and counts as a failed attempt). Results are gathered as they finish
(:class:`distributed.as_completed`), and after each one the manifest ``OUT/batch.json``
is rewritten atomically (:func:`~robopercept.fileio.atomic_write`): one record per
item with its ``status`` (``pending``, ``ok``, ``failed``, ``skipped``: done by an
earlier run and resumed, ``cancelled``: pending when the batch was interrupted), its
``attempts``, ``seconds`` (the worker's time on the last attempt), ``worker`` (its
address), ``error`` (the last one) and ``outputs`` (paths relative to ``OUT``), and
the job's ``options`` (every one, defaults filled in). A failed item does not stop the
batch. Inputs are only read.

Resuming (``resume=True``, ``robopercept batch --resume``) reads the manifest with
:func:`read_manifest`, which checks every field's type (a damaged manifest is a
:class:`~robopercept.errors.FileFormatError` naming ``--overwrite``), and refuses a
manifest of another job or other options (:class:`~robopercept.errors.ArgumentError`,
exit 2, naming ``--overwrite``; the manifest is left as it was), since the skipped
items would keep results of the old options. An item counts as done only when its
status is ``ok`` or ``skipped`` and every recorded output is a file inside its own
folder ``OUT/<item>/``; any other item runs again.

A scheduler that goes away mid-batch ends it with :class:`SchedulerGoneError` once
the manifest is written: the items done are kept, the others recorded ``failed`` with
the reason, and ``resume`` finishes them. A Ctrl-C at any point, the cluster's start
included, records every item not done ``cancelled``.

Nothing of Dask reaches the terminal: while a batch runs, the log lines of Dask
(scheduler, nannies, client, and workers in this process) go to ``OUT/batch.log``
(:data:`LOG`, appended to by each run) with this module's own lines (the run's start
and end, each failed attempt with the item's traceback); the worker processes of a
local cluster write theirs there too (``Compute Failed`` and its traceback), from their
start. The terminal (stderr) shows the progress bar and one line per failed item,
``batch JOB: ITEM (INPUT) failed: ERROR`` with the error as the manifest records it.
The worker processes of a local cluster never see a Ctrl-C: the terminal sends it to
the whole process group, and the workers are started with SIGINT blocked, so this
process alone stops the batch and closes them (no ``KeyboardInterrupt`` traceback from
each; the command prints its one ``interrupted`` line). The workers of a cluster
reached by address keep their own logs.

Wall time of a batch of :math:`n` items on :math:`w` workers, each item taking
:math:`t` seconds, is about

.. math::  T(n, w) \\approx T_0 + \\lceil n / w \\rceil \\, t + n \\, c

with :math:`T_0` the cluster start-up (and the import of robopercept in each worker)
and :math:`c` the per-item scheduling overhead (``docs/scale.md`` has measured values).
"""

from __future__ import annotations

import contextlib
import functools
import glob
import ipaddress
import json
import logging
import os
import re
import reprlib
import shutil
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from robopercept.errors import ArgumentError, FileFormatError, InputError, RoboperceptError
from robopercept.fileio import atomic_write, read_json, write_error
from robopercept.imaging.io import IMAGE_EXTENSIONS

__all__ = [
    "IMAGE_SUFFIXES",
    "JOBS",
    "JOB_OPTIONS",
    "LOG",
    "MANIFEST",
    "MAX_OUTPUTS",
    "MAX_WORKERS",
    "REQUIRED",
    "STATUSES",
    "STEREO_PAIRS",
    "WORKER_CONFIG",
    "BatchResult",
    "SchedulerGoneError",
    "find_inputs",
    "item_names",
    "local_cluster",
    "read_manifest",
    "run_batch",
    "run_item",
    "stereo_pair",
]

#: each job's options (:func:`run_item` says what they mean) with their defaults; an
#: option whose default is None and that :data:`REQUIRED` names must be given
JOB_OPTIONS: dict[str, dict[str, Any]] = {
    "cloud": {"voxel": None, "planes": None, "seed": 0},
    "edges": {"method": "canny", "sigma": 1.0},
    "features": {"detector": "harris", "max": 500},
    "stereo": {"method": "sgm", "max_disparity": None, "min_disparity": 0, "lr_check": 1.0},
    "plane-track": {"max_frames": None},
    "nn-predict": {"model": None, "top_k": 3},
    "nn-detect": {"model": None, "score_thresh": None},
    "nn-segment": {"model": None, "score_thresh": None},
    "nn-pose": {"model": None},
    "nn-cloud": {"model": "pointnet", "points": None, "seed": 0},
}
#: the jobs :func:`run_batch` runs
JOBS = tuple(JOB_OPTIONS)
#: the options a job cannot run without
REQUIRED = {"stereo": ("max_disparity",), "nn-predict": ("model",)}
#: the manifest's file name inside ``OUT``
MANIFEST = "batch.json"
#: the log's file name inside ``OUT``: the Dask scheduler's, nannies' and local
#: workers' log lines (``Compute Failed`` and its traceback among them), this
#: process's Dask client lines, and one line per run, per failed attempt (with the
#: item's traceback) and per interruption; appended to by every run (``--resume``)
LOG = "batch.log"
#: an item's states in the manifest
STATUSES = ("pending", "ok", "failed", "skipped", "cancelled")
#: files an image job takes from a folder
IMAGE_SUFFIXES = IMAGE_EXTENSIONS
#: the file stems of a stereo pair folder's left and right images, the first pair
#: present wins: ``left``/``right``, Middlebury 2014 ``im0``/``im1``, Middlebury
#: 2001/2003 ``im2``/``im6``, Middlebury 2005/2006 ``view1``/``view5``
STEREO_PAIRS = (("left", "right"), ("im0", "im1"), ("im2", "im6"), ("view1", "view5"))
_CLOUD_SUFFIXES = (".pcd", ".ply")
_RECORDING_SUFFIXES = (".bag", ".db3")  # RealSense recordings (ROS 1 bag, ROS 2 SQLite)
_NN_CLOUD_SUFFIXES = (".pcd", ".ply", ".off")
#: Dask configuration the local workers start with (``docs/scale.md`` gives it as a
#: YAML file for the workers of a cluster):
#:
#: - ``MALLOC_TRIM_THRESHOLD_`` unset (``pre-spawn-environ``). Dask's nanny sets it to
#:   65536 (to hand freed memory back to the system) before it starts each worker; any
#:   such variable turns off glibc's dynamic mmap threshold, so every large array is a
#:   fresh ``mmap`` whose pages fault in again: ``plane-track`` ran 1.85x slower per
#:   item with it (1.84 s against 1.00 s on a 20-frame recording).
#: - ``NUMBA_NUM_THREADS=1`` in the worker process (``environ``; never in this
#:   process, whose numba may have started its threads: a changed value makes every
#:   later compilation here fail), one thread per worker as Dask's own
#:   ``OMP_NUM_THREADS=1``. The ``parallel=True`` kernels (colour selection, stereo)
#:   would otherwise start a thread per core in every worker: two workers on two cores
#:   took 2.50 s per ``plane-track`` item instead of 1.31 s.
WORKER_CONFIG = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.nanny.environ.NUMBA_NUM_THREADS": 1,
}
#: the shipped point-cloud classifiers nn-cloud takes by name
_CLOUD_CLASSIFIERS = ("pointnet", "dgcnn")


class SchedulerGoneError(RoboperceptError, ConnectionError):
    """The Dask scheduler of a batch went away (stopped, killed, unreachable) before
    every item finished. Raised by :func:`run_batch` after the manifest is written:
    the items done keep their outputs, the others are recorded ``failed`` with the
    reason, and ``resume=True`` (``--resume``) finishes them. The command line exits
    1 with its message."""


def _check_job(job: str) -> str:
    if not isinstance(job, str) or job not in JOBS:
        raise InputError(f"job must be one of {', '.join(JOBS)}; got {reprlib.repr(job)}")
    return job


#: the address forms :func:`run_batch` takes, for messages
_SCHEDULER_FORMS = (
    "'local' or the address of a running Dask cluster, tcp://HOST:PORT (HOST a name, an "
    "IPv4 address or an [IPv6] address in brackets, PORT 1-65535)"
)
_HOSTNAME = re.compile(
    r"(?=.{1,253}$)[A-Za-z0-9_](?:[A-Za-z0-9_-]{0,61}[A-Za-z0-9_])?"
    r"(?:\.[A-Za-z0-9_](?:[A-Za-z0-9_-]{0,61}[A-Za-z0-9_])?)*\.?"
)
#: schemes Dask knows that a batch cannot use, and why
_OTHER_SCHEMES = {
    "tls": "needs certificates (a distributed.Security) that a batch does not pass",
    "ucx": "needs UCX-Py and its network hardware",
    "ws": "needs the websockets package and a cluster started for it",
    "wss": "needs the websockets package and certificates",
    "inproc": "reaches only a cluster inside this process",
}


def _check_scheduler(scheduler: Any) -> str:
    """``scheduler`` after checking that it is ``"local"`` or ``tcp://HOST:PORT`` (before
    anything connects); anything else is an :class:`ArgumentError` saying the forms."""
    if scheduler == "local" and isinstance(scheduler, str):
        return scheduler
    if not isinstance(scheduler, str):
        raise ArgumentError(
            f"scheduler must be {_SCHEDULER_FORMS}; got {type(scheduler).__name__} "
            f"{reprlib.repr(scheduler)}"
        )
    got = f"got {reprlib.repr(scheduler)}"
    scheme, sep, rest = scheduler.partition("://")
    if not sep:
        host, colon, port = scheduler.rpartition(":")
        hint = f": write tcp://{scheduler}" if colon and host and port.isdigit() else ""
        raise ArgumentError(f"scheduler must be {_SCHEDULER_FORMS}; {got}{hint}")
    if scheme != "tcp":
        why = _OTHER_SCHEMES.get(scheme.lower(), "is not one a batch can use")
        if scheme.lower() == "tcp":
            why = "is written tcp:// (lower case)"
        raise ArgumentError(
            f"scheduler must be {_SCHEDULER_FORMS}; {got}: the {scheme}:// protocol {why}"
        )
    if rest.startswith("["):
        inside, bracket, after = rest[1:].partition("]")
        try:
            ipaddress.IPv6Address(inside)
        except ValueError:
            bracket = ""
        if not bracket or not after.startswith(":"):
            raise ArgumentError(
                f"scheduler must be {_SCHEDULER_FORMS}; {got}: the [IPv6] host or its :PORT "
                "is missing or malformed"
            )
        port = after[1:]
    else:
        host, colon, port = rest.rpartition(":")
        if not colon:
            raise ArgumentError(
                f"scheduler must be {_SCHEDULER_FORMS}; {got}: the port is missing (Dask listens "
                "on 8786 unless told otherwise)"
            )
        if not _HOSTNAME.fullmatch(host):
            raise ArgumentError(
                f"scheduler must be {_SCHEDULER_FORMS}; {got}: {reprlib.repr(host)} is not a "
                "host name or address"
            )
    if not (port.isascii() and port.isdigit() and len(port) <= 5 and 1 <= int(port) <= 65535):
        raise ArgumentError(
            f"scheduler must be {_SCHEDULER_FORMS}; {got}: the port must be a number "
            "from 1 to 65535"
        )
    return scheduler


def _is_recording(path: Path) -> bool:
    """A TUM-style recording folder (``rgb.txt`` and ``depth.txt``, as synth-rgbd
    writes)."""
    return (path / "rgb.txt").is_file() and (path / "depth.txt").is_file()


def stereo_pair(folder: str | os.PathLike[str]) -> tuple[Path, Path] | None:
    """The left and right images of a stereo pair folder, or None when it holds no pair.

    The first of :data:`STEREO_PAIRS` whose two stems both name an image in the folder
    (any of :data:`IMAGE_SUFFIXES`, case-insensitive) is the pair.

    Parameters
    ----------
    folder : path

    Returns
    -------
    (Path, Path) or None

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for n in ("im2.png", "im6.png", "disp2.png"):
    ...     _ = (d / n).write_bytes(b"")
    >>> [p.name for p in stereo_pair(d)]
    ['im2.png', 'im6.png']
    """
    path = Path(folder)
    if not path.is_dir():
        return None
    images: dict[str, Path] = {}
    for p in sorted(path.iterdir()):
        if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES:
            images.setdefault(p.stem.lower(), p)
    for left, right in STEREO_PAIRS:
        if left in images and right in images:
            return images[left], images[right]
    return None


#: the jobs whose inputs are folders, and the test a folder must pass to be one
_FOLDER_JOBS: dict[str, Callable[[Path], bool]] = {
    "plane-track": _is_recording,
    "stereo": lambda p: stereo_pair(p) is not None,
}
_FOLDER_WHAT = {
    "plane-track": "a recording folder (rgb.txt and depth.txt) or a .bag/.db3 recording",
    "stereo": "a stereo pair folder (" + ", ".join(f"{a}/{b}" for a, b in STEREO_PAIRS) + ")",
}


def _matches(job: str, path: Path) -> bool:
    if job == "plane-track" and path.is_file():
        return path.suffix.lower() in _RECORDING_SUFFIXES
    if job in _FOLDER_JOBS:
        return path.is_dir() and _FOLDER_JOBS[job](path)
    suffixes = {"cloud": _CLOUD_SUFFIXES, "nn-cloud": _NN_CLOUD_SUFFIXES}.get(job, IMAGE_SUFFIXES)
    return path.is_file() and path.suffix.lower() in suffixes


def find_inputs(job: str, inputs: Iterable[str | os.PathLike[str]]) -> list[Path]:
    """The inputs of ``job`` named by files, folders and glob patterns.

    A file is taken as given; a folder gives its matching files (sorted, not
    recursive): ``.pcd``/``.ply`` for ``cloud``, ``.pcd``/``.ply``/``.off`` for
    ``nn-cloud``, images (:data:`IMAGE_SUFFIXES`) for ``edges``, ``features`` and the
    image ``nn-*`` jobs. For ``plane-track`` a recording folder (``rgb.txt`` and
    ``depth.txt``) or a RealSense recording (``.bag``, ``.db3``), for ``stereo`` a pair
    folder (:func:`stereo_pair`), is one input, and another folder gives its such
    sub-folders (and recordings). A pattern with ``*``, ``?`` or
    ``[`` is expanded (sorted) and each match treated as above. Duplicates are
    dropped, the first kept.

    Parameters
    ----------
    job : str
        One of :data:`JOBS`.
    inputs : iterable of path or str

    Returns
    -------
    list of Path

    Raises
    ------
    InputError
        An unknown job, an input that does not exist or matches nothing, or no input.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for n in ("b.pcd", "a.ply", "notes.txt"):
    ...     _ = (d / n).write_text("")
    >>> [p.name for p in find_inputs("cloud", [d])]
    ['a.ply', 'b.pcd']
    """
    _check_job(job)
    inputs = list(inputs)
    found: list[Path] = []
    for raw in inputs:
        text = os.fspath(raw)
        if any(c in text for c in "*?["):
            paths = [Path(p) for p in sorted(glob.glob(text))]
            if not paths:
                raise InputError(f"{text}: the pattern matches no file: check the input")
        else:
            paths = [Path(text)]
        for path in paths:
            if not path.exists():
                raise InputError(f"{path}: no such file or folder: check the input")
            folder_job = job in _FOLDER_JOBS
            if path.is_dir() and not (folder_job and _FOLDER_JOBS[job](path)):
                found += [p for p in sorted(path.iterdir()) if _matches(job, p)]
            elif _matches(job, path) or (path.is_file() and not folder_job):
                found.append(path)  # a file named explicitly: the job judges it
            else:
                raise InputError(
                    f"{path}: not {_FOLDER_WHAT[job]} for {job}: give such folders or "
                    "folders holding them"
                )
    unique = list(dict.fromkeys(found))
    if not unique:
        what = {
            "cloud": ".pcd/.ply files",
            "nn-cloud": ".pcd/.ply/.off files",
            "plane-track": "recording folders or .bag/.db3 recordings",
            "stereo": "stereo pair folders",
        }
        raise InputError(
            f"no input for {job}: expected {what.get(job, 'image files')}; got "
            f"{', '.join(os.fspath(i) for i in inputs) or 'nothing'}"
        )
    return unique


def item_names(paths: Sequence[str | os.PathLike[str]]) -> list[str]:
    """One folder name per input: its file name without the suffix (a folder's name),
    made unique with ``_2``, ``_3``, ... in the order given (and never :data:`MANIFEST`
    or :data:`LOG`, the batch's own files).

    Parameters
    ----------
    paths : sequence of path or str

    Returns
    -------
    list of str

    Examples
    --------
    >>> item_names(["a/bun0.pcd", "b/bun0.pcd", "c/milk.ply", "rec/seq1"])
    ['bun0', 'bun0_2', 'milk', 'seq1']
    """
    names: list[str] = []
    taken: set[str] = set()
    for p in paths:
        path = Path(p)
        base = (path.stem if path.suffix else path.name) or "item"
        base = base.replace(os.sep, "_").lstrip(".") or "item"
        name, k = base, 1
        while name in taken or name in (MANIFEST, LOG):
            k += 1
            name = f"{base}_{k}"
        taken.add(name)
        names.append(name)
    return names


def _options(job: str, options: Mapping[str, Any] | None) -> dict[str, Any]:
    """The job's options, defaults filled in, checked before any item runs."""
    from robopercept._checks import check_choice, check_int, check_real

    defaults = JOB_OPTIONS[job]
    opts = dict(options or {})
    unknown = sorted(set(opts) - set(defaults))
    if unknown:
        raise InputError(
            f"options {unknown} do not apply to {job}; it takes {', '.join(defaults) or 'none'}"
        )
    opts = {k: opts.get(k, v) for k, v in defaults.items()}
    for name in REQUIRED.get(job, ()):
        if opts[name] is None:
            raise InputError(f"the {job} job needs {name}")
    if job == "edges":
        check_choice(opts["method"], "method", ("canny", "sobel"))
    elif job == "stereo":
        check_choice(opts["method"], "method", ("sgm", "bm"))
        opts["max_disparity"] = check_int(opts["max_disparity"], "max_disparity", 1)
        opts["min_disparity"] = check_int(opts["min_disparity"], "min_disparity")
        if opts["min_disparity"] >= opts["max_disparity"]:
            raise InputError(
                f"min_disparity {opts['min_disparity']} must be below max_disparity "
                f"{opts['max_disparity']}"
            )
        if opts["lr_check"] is not None:
            opts["lr_check"] = check_real(opts["lr_check"], "lr_check", 0.0)
    elif job == "nn-predict":
        opts["top_k"] = check_int(opts["top_k"], "top_k", 1)
    if job.startswith("nn-"):
        opts["model"] = _model_option(job, opts["model"])
    return opts


def _model_option(job: str, model: Any) -> str | None:
    """``model`` of an nn job, checked on this machine: a shipped name, or an existing
    run folder or model file (as a string)."""
    from robopercept.nn.shipped import SHIPPED

    kind = job.removeprefix("nn-")
    names = _CLOUD_CLASSIFIERS if kind == "cloud" else tuple(SHIPPED.get(kind, {}))
    if model is None or (isinstance(model, str) and model in names):
        return model
    if not isinstance(model, (str, os.PathLike)):
        raise InputError(f"model must be a path or a shipped name; got {model!r}")
    if not Path(model).exists():
        shipped = f"one of {', '.join(names)}, " if names else ""
        raise InputError(
            f"model {os.fspath(model)}: no such file or folder: give {shipped}a run folder "
            "or a model file"
        )
    # absolute: the workers need not share this process's working folder, and the
    # manifest compares it on --resume whatever folder that is run from
    return os.path.abspath(model)


def _files(folder: Path, root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in folder.rglob("*") if p.is_file())


def run_item(
    job: str,
    source: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    options: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Run ``job`` on one input, writing its files into ``out_dir`` (emptied first).

    ``cloud``: :func:`~robopercept.pipelines.process_cloud` (options ``voxel``,
    ``planes`` as ``(n, threshold)``, ``seed``), ``segments.ply`` (coloured by segment
    with a ``label`` field when ``planes`` is given) and ``summary.json`` (the steps).
    ``edges``: ``edges.png``, Canny (default thresholds 50 and 150 grey levels, scaled
    for 16-bit images) or the Sobel magnitude (``method``, ``sigma``). ``features``:
    :func:`~robopercept.features.harris_corners` (``detector`` ``harris`` or
    ``shi-tomasi``, at most ``max``) into ``keypoints.json``. ``stereo``: the pair of
    a folder (:func:`stereo_pair`) matched by
    :func:`~robopercept.depth.semi_global_matching` or
    :func:`~robopercept.depth.block_matching` (``method`` ``sgm``/``bm`` with the
    defaults of ``robopercept stereo``, ``max_disparity`` (required),
    ``min_disparity``, ``lr_check`` in pixels or None), ``disparity.npy`` (float32,
    NaN rejected) and ``disparity.png``
    (:func:`~robopercept.viz.plot.disparity_picture`). ``plane-track``:
    :func:`~robopercept.pipelines.plane_outputs.run_plane_tracking` of the recording
    folder (:class:`~robopercept.sources.TUMFolderSource`) or ``.bag``/``.db3`` file
    (:class:`~robopercept.sources.realsense.RealSenseSource`), no video, ``max_frames``:
    its outputs and ``summary.json``.

    The ``nn-*`` jobs import torch only on the worker, and load their model once per
    worker process. ``nn-predict``: :func:`~robopercept.nn.classification.run.predict` (what
    ``robopercept nn predict`` runs) with the run folder or checkpoint ``model``
    (required) into ``prediction.json`` (``file`` and the ``top_k`` most probable
    classes). ``nn-detect``, ``nn-segment``, ``nn-pose``: the images form of
    ``robopercept nn detect|segment|pose`` (:func:`~robopercept.nn.predict.\
load_image_predictor`; ``model`` a shipped name of :data:`~robopercept.nn.shipped.\
SHIPPED`, default the command's, or a run folder or model file; ``score_thresh`` for
    detect and segment, default the command's) into ``prediction.json`` (``file`` and
    :meth:`~robopercept.nn.predict.ImagePrediction.record`) and the command's
    pictures named ``prediction*.png``. ``nn-cloud``:
    :func:`~robopercept.nn.cloud.run.classify_cloud_file` (what ``robopercept nn cloud``
    runs) with the classifier ``model`` (``pointnet``, the default, ``dgcnn`` or a
    ``model.pt`` file), ``points`` sampled (default: the model's) with ``seed``, into
    ``prediction.json`` (``class``, ``probabilities``, most probable first,
    ``points``, ``file``).

    Parameters
    ----------
    job : str
        One of :data:`JOBS`.
    source : path
        The input file (a recording folder or file for ``plane-track``, a pair folder
        for ``stereo``); only read.
    out_dir : path
        The item's folder; created, and emptied when it exists.
    options : mapping, optional
        The job's options named above.

    Returns
    -------
    dict
        ``outputs`` (file names in ``out_dir``, sorted) and ``summary`` (a small
        JSON-able dict of the result).

    Raises
    ------
    InputError
        An unknown job or option.
    FileFormatError, DegenerateError
        From the job, for a file it cannot read or data it refuses.

    Examples
    --------
    >>> import tempfile
    >>> from robopercept.imaging import sample_image_path
    >>> out = Path(tempfile.mkdtemp()) / "sample"
    >>> run_item("edges", sample_image_path(), out)["outputs"]
    ['edges.png']
    """
    opts = _options(_check_job(job), options)
    src, out = Path(source), Path(out_dir)
    if out.exists():
        shutil.rmtree(out)  # a rerun (a retry, a worker that died) starts clean
    out.mkdir(parents=True)
    summary = _RUNNERS[job](src, out, opts)
    return {"outputs": _files(out, out), "summary": summary}


def _run_cloud(src: Path, out: Path, opts: dict[str, Any]) -> dict[str, Any]:
    import numpy as np

    from robopercept.pipelines.cloud import process_cloud
    from robopercept.pointcloud import read_point_cloud, write_point_cloud
    from robopercept.viz.colormap import label_colors

    res = process_cloud(
        read_point_cloud(src), voxel=opts["voxel"], planes=opts["planes"], rng=opts["seed"]
    )
    cloud = res.cloud
    if opts["planes"] is not None:  # as robopercept cloud: coloured by segment
        colors = label_colors(res.segment, background=(128, 128, 128)) / 255.0
        cloud = cloud.with_colors(colors.astype(np.float64)).with_labels(res.segment)
    write_point_cloud(out / "segments.ply", cloud)
    summary = {"points": len(cloud.points), "planes": [p["inliers"] for p in res.planes]}
    atomic_write(out / "summary.json", json.dumps({**summary, "steps": res.steps}, indent=2))
    return summary


def _run_edges(src: Path, out: Path, opts: dict[str, Any]) -> dict[str, Any]:
    import numpy as np

    from robopercept.imaging import canny, gaussian_blur, gradient, read_image, write_image
    from robopercept.imaging.edges import grey_level_scale

    gray = read_image(src, mode="gray")
    if opts["method"] == "canny":
        scale = grey_level_scale(gray.dtype)
        edges = canny(gray, 50.0 * scale, 150.0 * scale, sigma=opts["sigma"])
        pic = edges.astype(np.uint8) * 255
    elif opts["method"] == "sobel":
        work = gaussian_blur(gray.astype(np.float32), opts["sigma"]) if opts["sigma"] else gray
        mag, _ = gradient(work)
        pic = np.round(mag / (float(mag.max()) or 1.0) * 255.0).astype(np.uint8)
        edges = pic > 63
    else:
        raise InputError(f"method must be canny or sobel; got {opts['method']!r}")
    write_image(out / "edges.png", pic)
    return {"edge_pixels": int(edges.sum())}


def _run_features(src: Path, out: Path, opts: dict[str, Any]) -> dict[str, Any]:
    from robopercept.features import harris_corners
    from robopercept.imaging import read_image

    kp = harris_corners(
        read_image(src, mode="gray"), method=opts["detector"], max_corners=opts["max"]
    )
    rows = [
        {"x": float(x), "y": float(y), "response": float(r)}
        for (x, y), r in zip(kp.xy, kp.response, strict=True)
    ]
    atomic_write(out / "keypoints.json", json.dumps(rows))
    return {"keypoints": len(rows)}


def _run_plane_track(src: Path, out: Path, opts: dict[str, Any]) -> dict[str, Any]:
    from robopercept.pipelines.plane_outputs import run_plane_tracking
    from robopercept.sources import TUMFolderSource
    from robopercept.sources.realsense import RealSenseSource

    bag = src.suffix.lower() in _RECORDING_SUFFIXES
    source = RealSenseSource(src) if bag else TUMFolderSource(src)
    summary = run_plane_tracking(
        source, out, max_frames=opts["max_frames"], video=False, progress=False
    )
    if summary.frames == 0:
        raise InputError(f"{src}: no frame was tracked ({summary.stopped or 'no readable frame'})")
    return {"frames": summary.frames, "stopped": summary.stopped}


def _run_stereo(src: Path, out: Path, opts: dict[str, Any]) -> dict[str, Any]:
    import numpy as np

    from robopercept.depth import block_matching, semi_global_matching
    from robopercept.imaging import read_image, write_image
    from robopercept.viz.plot import disparity_picture

    pair = stereo_pair(src)
    if pair is None:
        raise InputError(f"{src}: {_FOLDER_WHAT['stereo']} was expected")
    left, right = (read_image(p, mode="rgb") for p in pair)
    if left.shape != right.shape:
        raise InputError(
            f"{src}: the left image is {left.shape[1]}x{left.shape[0]}, the right "
            f"{right.shape[1]}x{right.shape[0]}: a rectified pair has one size"
        )
    match = semi_global_matching if opts["method"] == "sgm" else block_matching
    disp = match(
        left,
        right,
        opts["max_disparity"],
        min_disparity=opts["min_disparity"],
        lr_check=opts["lr_check"],
    )
    np.save(out / "disparity.npy", disp.astype(np.float32))
    picture = disparity_picture(
        disp,
        method=opts["method"],
        min_disparity=opts["min_disparity"],
        max_disparity=opts["max_disparity"],
        lr_check=opts["lr_check"],
    )
    write_image(out / "disparity.png", picture)
    finite = np.isfinite(disp)
    return {
        "left": pair[0].name,
        "right": pair[1].name,
        "valid_percent": round(100.0 * float(finite.mean()), 3),
        "median_disparity": float(np.nanmedian(disp)) if finite.any() else None,
    }


_MODELS: dict[tuple[Any, ...], Any] = {}  # loaded models, per worker process


def _loaded(key: tuple[Any, ...], load: Callable[[], Any]) -> Any:
    """``load()`` once per worker process and ``key``."""
    if key not in _MODELS:
        _MODELS[key] = load()
    return _MODELS[key]


def _run_nn_predict(src: Path, out: Path, opts: dict[str, Any]) -> dict[str, Any]:
    from robopercept.nn.classification.run import predict_loaded
    from robopercept.nn.classification.saved import load_run

    model, arch = _loaded(("predict", opts["model"]), lambda: load_run(opts["model"]))
    pred = predict_loaded(model, arch, [src], top_k=opts["top_k"])[0]
    top = [{"class": c, "probability": float(p)} for c, p in pred.top]
    atomic_write(out / "prediction.json", json.dumps({"file": str(src), "top": top}, indent=2))
    return {"class": top[0]["class"], "probability": top[0]["probability"]}


def _run_nn_image(src: Path, out: Path, opts: dict[str, Any], kind: str) -> dict[str, Any]:
    from robopercept.nn.predict import load_image_predictor

    settings: dict[str, Any] = {"score_thresh": opts["score_thresh"]} if kind != "pose" else {}
    key = (kind, opts["model"], *settings.items())
    predictor = _loaded(key, lambda: load_image_predictor(kind, opts["model"], **settings))
    pred = predictor.predict_file(src)
    record = {"file": str(src), **pred.record()}
    atomic_write(out / "prediction.json", json.dumps(record, indent=2, allow_nan=False))
    pred.write(out, "prediction")
    counts = {k: len(v) for k, v in record.items() if isinstance(v, list) and k != "file"}
    return {k: counts[k] for k in ("detections", "instances", "keypoints") if k in counts}


def _run_nn_cloud(src: Path, out: Path, opts: dict[str, Any]) -> dict[str, Any]:
    from robopercept.nn.cloud.run import classify_cloud_file
    from robopercept.nn.cloud.train import load_cloud_model
    from robopercept.nn.shipped import resolve_model

    path = resolve_model("cloud", opts["model"])
    model, info = _loaded(("cloud", str(path.resolve())), lambda: load_cloud_model(path))
    res = classify_cloud_file(src, model, info, n_points=opts["points"], rng=opts["seed"])
    prediction = res.to_dict()
    atomic_write(out / "prediction.json", json.dumps(prediction, indent=2))
    return {"class": res.label, "probability": prediction["probabilities"][res.label]}


_RUNNERS: dict[str, Callable[[Path, Path, dict[str, Any]], dict[str, Any]]] = {
    "cloud": _run_cloud,
    "edges": _run_edges,
    "features": _run_features,
    "stereo": _run_stereo,
    "plane-track": _run_plane_track,
    "nn-predict": _run_nn_predict,
    "nn-detect": functools.partial(_run_nn_image, kind="detect"),
    "nn-segment": functools.partial(_run_nn_image, kind="segment"),
    "nn-pose": functools.partial(_run_nn_image, kind="pose"),
    "nn-cloud": _run_nn_cloud,
}


def _task(
    job: str, source: str, out_dir: str, options: dict[str, Any], delay: float
) -> dict[str, Any]:
    """What a worker runs for one item: :func:`run_item`, timed, with the worker's
    address."""
    from distributed import get_worker

    t0 = time.perf_counter()
    if delay > 0:
        time.sleep(delay)
    result = run_item(job, source, out_dir, options)
    result["seconds"] = round(time.perf_counter() - t0, 4)
    try:
        result["worker"] = get_worker().address
    except ValueError:  # run outside a worker
        result["worker"] = ""
    return result


@dataclass
class BatchResult:
    """What :func:`run_batch` did.

    Attributes
    ----------
    job : str
    out : Path
        The output folder; the manifest is ``out / "batch.json"``.
    scheduler : str
        ``"local"`` or the cluster's address.
    workers : int
        Workers the batch ran on.
    seconds : float
        Wall time, cluster start-up included.
    items : list of dict
        The manifest's records (``item``, ``input``, ``status``, ``seconds``,
        ``error``, ``outputs``), in input order.
    """

    job: str
    out: Path
    scheduler: str
    workers: int
    seconds: float
    items: list[dict[str, Any]] = field(default_factory=list)

    def count(self, status: str) -> int:
        """Items of ``status`` (``ok``, ``failed``, ``skipped``, ``cancelled``)."""
        return sum(r["status"] == status for r in self.items)

    def first_failure(self) -> dict[str, Any] | None:
        """The first failed item when every item this run ran failed (a batch that did
        nothing: the command exits 1), else None."""
        ran = [r for r in self.items if r["status"] in ("ok", "failed")]
        return ran[0] if ran and all(r["status"] == "failed" for r in ran) else None

    def to_dict(self) -> dict[str, Any]:
        """The JSON summary: the fields, counts per status and items per second."""
        n = len(self.items)
        return {
            "job": self.job,
            "out": str(self.out),
            "manifest": str(self.out / MANIFEST),
            "scheduler": self.scheduler,
            "workers": self.workers,
            "items": n,
            **{s: self.count(s) for s in ("ok", "failed", "skipped", "cancelled")},
            "seconds": round(self.seconds, 3),
            "items_per_second": round(n / self.seconds, 4) if self.seconds > 0 else 0.0,
            "results": self.items,
        }


MAX_OUTPUTS = 10_000
"""The most output files one item's manifest record may list: every job writes a
handful, and ``--resume`` checks each listed file (a stat and a path resolution),
so a damaged manifest listing millions would stall it."""

MAX_WORKERS = 256
"""The most local workers :func:`run_batch` and :func:`local_cluster` start: each is
a process (about 100 MiB and a second to start); more than a few per core only
thrashes, and an unbounded count (``--workers 1000000``) would exhaust the machine."""


def read_manifest(out: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The manifest ``OUT/batch.json`` of an earlier batch, checked, or None when absent.

    Read with :func:`robopercept.fileio.read_json` (the bounded reading policy), then
    every field :func:`run_batch` uses is checked: ``job`` a string, ``options`` (when
    present) an object with string keys, ``items`` a list of objects, each with ``item``
    (a non-empty string), ``input`` (a string), ``status`` (one of :data:`STATUSES`),
    ``outputs`` (a list of at most :data:`MAX_OUTPUTS` strings) and, when present,
    ``attempts`` (an integer >= 0), ``seconds`` (a number or null), ``worker`` and
    ``error`` (strings). Other keys (the counts of :meth:`BatchResult.to_dict`,
    ``summary``) are not used.

    Parameters
    ----------
    out : path
        The batch's output folder.

    Returns
    -------
    dict or None
        ``job``, ``options`` (absent in a manifest written before robopercept recorded
        them) and ``items`` (one record per item), as the file has them.

    Raises
    ------
    FileFormatError
        The manifest exists but is a folder, unreadable, not JSON, nested too deep, or
        a field has the wrong type; the message names the file, the field and the fix
        (``--overwrite``, ``overwrite=True``: start the batch again).

    Examples
    --------
    >>> import tempfile
    >>> read_manifest(tempfile.mkdtemp()) is None
    True
    """
    path = Path(out) / MANIFEST
    if not os.path.lexists(path):
        return None
    fix = "start the batch again with --overwrite (overwrite=True), or choose another output folder"
    try:
        data = read_json(path, "a batch manifest (batch.json)")
    except FileFormatError as exc:
        raise FileFormatError(f"{exc}: the batch manifest cannot be resumed: {fix}") from None

    def bad(where: str, expected: str, value: Any) -> FileFormatError:
        shown = f"{type(value).__name__} {reprlib.repr(value)}"
        return FileFormatError(
            f"{path}: {where} must be {expected}; got {shown}: the manifest is damaged "
            f"(not as run_batch writes it): {fix}"
        )

    if not isinstance(data, dict):
        raise bad("the document", "an object", data)
    if not isinstance(data.get("job"), str):
        raise bad("job", "a string", data.get("job"))
    if "options" in data:
        opts = data["options"]
        if not isinstance(opts, dict) or not all(isinstance(k, str) for k in opts):
            raise bad("options", "an object", opts)
    items = data.get("items")
    if not isinstance(items, list):
        raise bad("items", "a list of records", items)
    optional: dict[str, tuple[Callable[[Any], bool], str]] = {
        "attempts": (_is_count, "an integer >= 0"),
        "seconds": (lambda v: v is None or _is_number(v), "a number or null"),
        "worker": (lambda v: isinstance(v, str), "a string"),
        "error": (lambda v: isinstance(v, str), "a string"),
    }
    for i, rec in enumerate(items):
        where = f"items[{i}]"
        if not isinstance(rec, dict):
            raise bad(where, "an object", rec)
        if not isinstance(rec.get("item"), str) or not rec["item"]:
            raise bad(f"{where}.item", "a non-empty string", rec.get("item"))
        if not isinstance(rec.get("input"), str):
            raise bad(f"{where}.input", "a string", rec.get("input"))
        if not isinstance(rec.get("status"), str) or rec["status"] not in STATUSES:
            raise bad(f"{where}.status", f"one of {', '.join(STATUSES)}", rec.get("status"))
        outputs = rec.get("outputs")
        if not isinstance(outputs, list) or not all(isinstance(o, str) for o in outputs):
            raise bad(f"{where}.outputs", "a list of strings", outputs)
        if len(outputs) > MAX_OUTPUTS:
            raise FileFormatError(
                f"{path}: {where}.outputs lists {len(outputs)} files; a job writes at most "
                f"{MAX_OUTPUTS} per item (--resume checks each one): the manifest is "
                f"damaged (not as run_batch writes it): {fix}"
            )
        for key, (ok, expected) in optional.items():
            if key in rec and not ok(rec[key]):
                raise bad(f"{where}.{key}", expected, rec[key])
    return data


def _is_count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _recorded(opts: Mapping[str, Any]) -> dict[str, Any]:
    """The options as the manifest records them (JSON: tuples as lists)."""
    return dict(json.loads(json.dumps(opts, default=str)))


def _check_resumable(
    previous: Mapping[str, Any], job: str, opts: dict[str, Any], path: Path
) -> None:
    """Refuse to resume the batch the manifest ``previous`` (at ``path``) records under
    another job or other options: its skipped items would keep the old results."""
    again = "give --overwrite to run every item again, or choose another output folder"
    if previous["job"] != job:
        raise ArgumentError(
            f"{path}: records a batch of the {reprlib.repr(previous['job'])} job, not {job}: "
            f"--resume continues only the same job: {again}"
        )
    if "options" not in previous:
        raise ArgumentError(
            f"{path}: records no options (an older or hand-written manifest), so "
            f"--resume cannot tell whether its items were made with these: {again}"
        )
    old, new = previous["options"], _recorded(opts)
    changed = []
    for k in sorted(set(old) | set(new)):
        if k not in new:
            changed.append(f"{reprlib.repr(k)} (the manifest has it; {job} takes no such option)")
        elif k not in old:
            changed.append(f"{k}={new[k]!r} (the manifest has no {k})")
        elif old[k] != new[k]:
            changed.append(f"{k}={new[k]!r} (the manifest has {reprlib.repr(old[k])})")
    if changed:
        raise ArgumentError(
            f"{path}: --resume under other options than the batch it records: "
            f"{'; '.join(changed)}; resuming would mix results of both: give the options "
            f"of that batch, or {again}"
        )


def _done(record: Mapping[str, Any], out: Path) -> bool:
    """Finished in an earlier run, every recorded output a file inside the item's own
    folder ``out/<item>/`` (no absolute path, ``..`` or link leading elsewhere)."""
    if record["status"] not in ("ok", "skipped") or not record["outputs"]:
        return False
    try:
        folder = (out / record["item"]).resolve()
        for o in record["outputs"]:
            rel = Path(o)
            if rel.is_absolute() or ".." in rel.parts or rel.parts[:1] != (record["item"],):
                return False
            target = (out / rel).resolve()
            if folder not in target.parents or not target.is_file():
                return False
    except (OSError, RuntimeError, ValueError):  # a link loop, a NUL byte
        return False
    return True


def _check_workers(workers: Any) -> int:
    """``workers`` as an int in ``[1, MAX_WORKERS]``."""
    from robopercept._checks import check_int

    workers = check_int(workers, "workers", 1)
    if workers > MAX_WORKERS:
        raise InputError(
            f"workers must be at most {MAX_WORKERS} (each local worker is a process of one "
            f"thread); got {workers}: give about the number of cores "
            f"({os.cpu_count() or 1} here)"
        )
    return workers


def local_cluster(workers: int = 2) -> Any:
    """A :class:`distributed.LocalCluster` as ``run_batch(scheduler="local")`` starts it.

    ``workers`` processes of one thread each, no dashboard, worker logs at ERROR only,
    started with :data:`WORKER_CONFIG` (``MALLOC_TRIM_THRESHOLD_`` unset,
    ``NUMBA_NUM_THREADS=1`` in the workers; this process's environment is left as it
    was). Close it (``close()`` or a ``with`` block) when done. (:func:`run_batch`
    starts it with the workers' logs in ``OUT/batch.log`` and SIGINT blocked in them.)

    Parameters
    ----------
    workers : int
        Worker processes, 1 to :data:`MAX_WORKERS`.

    Returns
    -------
    distributed.LocalCluster

    Raises
    ------
    InputError
        ``workers`` not an integer >= 1.

    Examples
    --------
    >>> from distributed import Client  # doctest: +SKIP
    >>> with local_cluster(1) as cluster, Client(cluster) as client:  # doctest: +SKIP
    ...     client.run(lambda: os.environ.get("NUMBA_NUM_THREADS"))
    {'tcp://127.0.0.1:40341': '1'}
    """
    import dask
    from distributed import LocalCluster

    workers = _check_workers(workers)
    with warnings.catch_warnings(), dask.config.set(WORKER_CONFIG):
        # its health-check HTTP server tries port 8787 first
        warnings.filterwarnings("ignore", "Port .* is already in use", UserWarning)
        return LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=40,  # logging.ERROR: the worker chatter stays off stderr
        )


def _worker_env() -> str | None:
    """On a worker: its ``MALLOC_TRIM_THRESHOLD_``."""
    return os.environ.get("MALLOC_TRIM_THRESHOLD_")


def _check_worker_env(client: Any) -> None:
    """Warn when a cluster's workers run with ``MALLOC_TRIM_THRESHOLD_`` set."""
    envs = client.run(_worker_env)
    slow = [a for a, trim in envs.items() if trim is not None]
    if slow:
        warnings.warn(
            f"{len(slow)} of {len(envs)} workers run with MALLOC_TRIM_THRESHOLD_ set (Dask's "
            "default), which made robopercept's jobs up to 1.9x slower here: start them "
            "with the Dask configuration in docs/scale.md (pipelines.batch.WORKER_CONFIG)",
            RuntimeWarning,
            stacklevel=3,
        )


#: this module's log lines (a run's start and end, each failed attempt): into
#: ``OUT/batch.log`` while a batch runs
_log = logging.getLogger(__name__)
#: the loggers of Dask and its stack whose lines go to ``OUT/batch.log`` instead of the
#: terminal while a batch runs, with the levels Dask's own logging set-up gives them
_DASK_LOGGERS = {
    "distributed": "INFO",
    "distributed.client": "WARNING",
    "distributed.gc": "WARNING",
    "tornado": "CRITICAL",
    "tornado.application": "ERROR",
    "bokeh": "ERROR",
    "asyncio": "WARNING",
}
#: the environment variable that carries the workers' logging configuration (Dask
#: reads ``DASK_*`` variables as configuration when a worker process imports it)
_WORKER_LOGGING_ENV = "DASK_DISTRIBUTED__LOGGING"


def _log_format() -> str:
    import dask

    return str(dask.config.get("distributed.admin.log-format"))


def _file_handler(path: Path) -> logging.Handler:
    """A handler appending to ``path``, with Dask's log format.

    A :class:`logging.handlers.MemoryHandler` of capacity 1 in front of a
    :class:`logging.FileHandler`: each record is written at once, and the handler is
    no :class:`logging.StreamHandler`, whose level a cluster's ``silence_logs`` sets
    to ERROR (``distributed.utils.silence_logging_cmgr``), which would keep the INFO
    lines out of the file."""
    import logging.handlers

    file = logging.FileHandler(path, mode="a", encoding="utf-8", delay=True)
    file.setFormatter(logging.Formatter(_log_format()))
    # a log line that cannot be written (a full disk) is lost, not a traceback on the
    # terminal; the manifest's own write reports the disk
    file.handleError = lambda record: None  # type: ignore[method-assign]
    return logging.handlers.MemoryHandler(1, flushLevel=logging.DEBUG, target=file)


def _check_log(path: Path) -> None:
    """Refuse a log ``path`` that is not a file this process can append to (a folder,
    a link: a resumed batch's own log is appended to) before anything runs."""
    if path.is_symlink() or (os.path.lexists(path) and not path.is_file()):
        raise InputError(
            f"{path}: exists and is not a file (a batch appends its log to {LOG}): "
            "remove it, or choose another output folder"
        )
    try:
        with open(path, "a", encoding="utf-8"):
            pass
    except OSError as exc:
        raise write_error(path, exc) from None


def _is_console(handler: logging.Handler) -> bool:
    """A handler that writes to a stream (the terminal: stderr or stdout), not a file."""
    return isinstance(handler, logging.StreamHandler) and not isinstance(
        handler, logging.FileHandler
    )


@contextlib.contextmanager
def _logs_to(path: Path) -> Iterator[None]:
    """Inside the block, the log lines of Dask (:data:`_DASK_LOGGERS`: the scheduler and
    nannies of a local cluster, workers in this process, the client) and of this
    module go to the file ``path`` (appended to), not the terminal: their console
    handlers are taken off and their lines do not propagate to the root logger's.
    Other handlers (a file a user set up) stay. Everything is put back on leaving."""
    handler = _file_handler(path)
    saved = []
    for name in (*_DASK_LOGGERS, __name__):
        logger = logging.getLogger(name)
        saved.append((logger, list(logger.handlers), logger.propagate, logger.level))
        keep = [h for h in logger.handlers if not _is_console(h)]
        if "." in name and name != __name__:  # its lines reach its parent's handlers
            # (Dask's logging set-up stops them propagating: without this, a line of
            # tornado.application, as a callback's error, went to logging's last-resort
            # handler, which prints the bare message on the terminal)
            logger.handlers = keep
            logger.propagate = True
        else:
            logger.handlers = [*keep, handler]
            logger.propagate = False
    logging.getLogger(__name__).setLevel(logging.INFO)
    try:
        yield
    finally:
        for logger, handlers, propagate, level in saved:
            logger.handlers = handlers
            logger.propagate = propagate
            logger.level = level
        handler.close()  # flushes and closes the file
        target = getattr(handler, "target", None)
        if target is not None:
            target.close()


def _worker_log_config(path: Path) -> dict[str, Any]:
    """The Dask configuration that sends the log lines of the local workers' processes
    (from their start: the ``Compute Failed`` lines and tracebacks, and any library's
    warnings logged there) to ``path``, appended to, instead of the terminal.

    Dask configures a process's logging from ``distributed.logging`` when the process
    imports it (``distributed.config.initialize_logging``), and reads ``DASK_*``
    environment variables as configuration; the nanny puts
    ``distributed.nanny.pre-spawn-environ`` into the environment of each worker process
    it spawns. So the configuration is a :func:`logging.config.dictConfig` dictionary
    in ``DASK_DISTRIBUTED__LOGGING`` there: :data:`_DASK_LOGGERS`' levels and a root
    handler appending to the file (:func:`_file_handler`'s pair). Empty when the user
    configured Dask's logging already (``distributed.logging-file-config`` or that
    variable): theirs is kept."""
    import dask

    if _WORKER_LOGGING_ENV in os.environ or dask.config.get(
        "distributed.logging-file-config", None
    ):
        return {}
    config = {
        "version": 1,
        "disable_existing_loggers": False,
        "formatters": {"dask": {"format": _log_format()}},
        "handlers": {
            "file": {
                "class": "logging.FileHandler",
                "filename": os.fspath(path.resolve()),
                "mode": "a",
                "encoding": "utf-8",
                "delay": True,
                "formatter": "dask",
            },
            "batch": {
                "class": "logging.handlers.MemoryHandler",
                "capacity": 1,
                "flushLevel": "DEBUG",
                "target": "file",
            },
        },
        "loggers": {name: {"level": level} for name, level in _DASK_LOGGERS.items()},
        "root": {"level": "WARNING", "handlers": ["batch"]},
    }
    return {f"distributed.nanny.pre-spawn-environ.{_WORKER_LOGGING_ENV}": repr(config)}


def _without_sigint(start: Callable[[], Any], then: contextlib.ExitStack | None = None) -> Any:
    """``start()`` run in a helper thread that blocks SIGINT; its result or exception.

    A thread starts with its creator's signal mask and a process with the mask of the
    thread that spawned it, kept across ``exec``. So the threads ``start()`` creates
    (a local cluster's event loop, which spawns the worker processes) and those
    processes have SIGINT blocked: a Ctrl-C at the terminal, which the terminal sends
    to the whole process group, reaches this process alone, which stops the batch and
    closes the cluster in order, instead of interrupting each worker (a
    ``KeyboardInterrupt`` traceback from each, and ``Nanny failed to start`` when the
    cluster was starting). The calling thread keeps SIGINT: a first Ctrl-C during the
    start is handled by the caller (:class:`StopSignals` records it and the start
    goes on); one that raises (a second) returns at once, the cluster is closed when
    its start ends, and only then ``then`` (the batch's log file, which the closing
    cluster still writes to: its callbacks move to the helper thread). Without
    ``signal.pthread_sigmask`` (Windows) ``start()`` runs here.

    The first multiprocessing queue of a process starts multiprocessing's resource
    tracker, and ``multiprocessing.resource_tracker.ensure_running`` ends by
    *unblocking* SIGINT and SIGTERM in the thread that started it (CPython 3.11 here),
    which would be the cluster's event loop: so the tracker is started first, from the
    calling thread."""
    if not hasattr(signal, "pthread_sigmask"):
        return start()
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    lock = threading.Lock()
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            value = start()
        except BaseException as exc:  # handed to the caller
            value = None
            box["error"] = exc
        with lock:
            box["value"] = value
            abandoned = box.get("abandoned")
        if abandoned is not None:
            _close_quietly(value)
            abandoned.close()

    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        thread = threading.Thread(target=run, name="robopercept batch: cluster start", daemon=True)
        thread.start()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
    try:
        thread.join()
    except BaseException:
        with lock:
            if "value" not in box:  # still starting: the helper closes it, then ``then``
                box["abandoned"] = then.pop_all() if then is not None else contextlib.ExitStack()
        if "abandoned" not in box:
            _close_quietly(box["value"])
        raise
    if "error" in box:
        raise box["error"]
    return box["value"]


def _close_quietly(cluster: Any) -> None:
    """Close an abandoned ``cluster`` (None: nothing), whatever its state: the process
    may be exiting (Dask's own exit handler closing it at the same time), and the
    batch already ends with the Ctrl-C that abandoned it."""
    if cluster is not None:
        with contextlib.suppress(BaseException):
            cluster.close()


def _connect(
    scheduler: str, workers: int, connect_timeout: float, logs: contextlib.ExitStack
) -> tuple[Any, Any]:
    """``(client, cluster)``: a new :func:`local_cluster` (cluster not None) or a client
    of the cluster at ``scheduler``. ``logs`` (the batch's log file) stays open until
    a cluster whose start a second Ctrl-C abandoned has closed; the client and the
    cluster are closed by ``logs.close()``, before the log file, from the moment they
    exist (registered while Ctrl-C waits: one that lands as this returns closes them
    too, their shutdown's lines still going to the file, not to the terminal at exit)."""
    from distributed import Client

    from robopercept.pipelines.plane_outputs import StopSignals

    if scheduler == "local":
        # a Ctrl-C that interrupts the cluster's start leaves it half-built (its atexit
        # close then fails with a traceback): the first one waits for the start, then
        # the cluster is closed and KeyboardInterrupt raised; a second one stops at once.
        # The workers never see it (_without_sigint): this process stops them.
        with StopSignals((signal.SIGINT,)) as stop:
            cluster = _without_sigint(lambda: local_cluster(workers), logs)
            logs.callback(cluster.close)
            client = Client(cluster)
            logs.callback(client.close)  # runs first: the client goes before its cluster
        if stop.received:
            raise KeyboardInterrupt  # the caller's logs.close() closes both
        return client, cluster
    try:
        client = Client(scheduler, timeout=connect_timeout)
        logs.callback(client.close)
        return client, None
    except (OSError, TimeoutError) as exc:
        raise InputError(
            f"--scheduler {scheduler}: no Dask scheduler answered within {connect_timeout:g} s "
            f"({type(exc).__name__}): start one (dask scheduler) and check the address, or "
            "use --scheduler local"
        ) from None
    except (ValueError, TypeError) as exc:  # an address Dask refuses after our check
        raise ArgumentError(
            f"scheduler must be {_SCHEDULER_FORMS}; got {scheduler!r}, which Dask refuses "
            f"({_error_text(exc)})"
        ) from None


def _error_text(exc: BaseException | None) -> str:
    """``"Type: first line"`` of an item's error (a future gives None for no error)."""
    if exc is None:
        return "the task ended without a result or an error (Dask gave none)"
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0]}" if text else type(exc).__name__


def _scheduler_gone(client: Any) -> bool:
    """Whether ``client`` lost its scheduler (it reconnects or closed)."""
    return getattr(client, "status", "running") != "running"


def run_batch(
    job: str,
    inputs: Iterable[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    *,
    scheduler: str = "local",
    workers: int = 2,
    retries: int = 1,
    resume: bool = False,
    overwrite: bool = False,
    connect_timeout: float = 10.0,
    options: Mapping[str, Any] | None = None,
    progress: bool = True,
    delay: float = 0.0,
) -> BatchResult:
    """Run ``job`` on every input on a Dask cluster, each item's files in ``OUT/<item>/``.

    Parameters
    ----------
    job : str
        One of :data:`JOBS` (:func:`run_item` says what each writes).
    inputs : iterable of path or str
        Files, folders and glob patterns (:func:`find_inputs`); only read.
    out : path
        The output folder. One that exists and is not empty is refused unless
        ``resume`` or ``overwrite``.
    scheduler : str
        ``"local"``: a :class:`distributed.LocalCluster` of ``workers`` processes with
        one thread each, closed at the end; or the address of a running scheduler
        (``tcp://HOST:PORT``, HOST a name, an IPv4 address or ``[IPv6]``, PORT 1-65535),
        whose workers share the file system. Other forms (``tls://``, ``ucx://``, no
        port) are refused before anything connects.
    workers : int
        Workers of the local cluster, 1 to :data:`MAX_WORKERS` (ignored for an address,
        but checked).
    retries : int
        More attempts at an item that raised (each resubmitted as a new task, which
        Dask may place on another worker); the record's ``attempts`` counts them.
    resume : bool
        Skip the items the manifest in ``out`` records as done whose outputs all
        exist inside their own folders (their status becomes ``skipped``); run the
        others. The manifest must record the same job and options (an
        :class:`~robopercept.errors.ArgumentError` otherwise, and the manifest is left
        as it was). Without a manifest every item runs.
    overwrite : bool
        Run every item again (each item's folder is emptied before it runs).
    connect_timeout : float
        Seconds to wait for the scheduler at an address.
    options : mapping, optional
        The job's options (:data:`JOB_OPTIONS`, :func:`run_item`), checked before the
        cluster starts (a model path, for instance, must exist here).
    progress : bool
        A progress bar on stderr with items per second, and one line per failed item
        when its last attempt fails (``batch JOB: ITEM (INPUT) failed: ERROR``, the
        manifest's ``error``). False: nothing on stderr. Dask's log lines go to
        ``OUT/batch.log`` either way (:data:`LOG`).
    delay : float
        Seconds each item sleeps on its worker before it runs (to watch a batch, or to
        test fault tolerance); 0 by default.

    Returns
    -------
    BatchResult
        Also in ``OUT/batch.json``, rewritten atomically after each finished item;
        the log in ``OUT/batch.log``.

    Raises
    ------
    InputError
        A bad argument, no input, an ``out`` that exists (refused), an
        ``OUT/batch.log`` that is not a file (a folder, a link), or a scheduler
        address that does not answer within ``connect_timeout``.
    robopercept.fileio.WriteError
        ``OUT/batch.log`` cannot be appended to (a read-only folder).
    ArgumentError
        A ``scheduler`` of another form than above; ``resume`` of a manifest that
        records another job or other options, or none (the message names
        ``--overwrite``).
    FileFormatError
        ``resume`` of a damaged manifest (:func:`read_manifest`).
    SchedulerGoneError
        The scheduler went away mid-batch; raised after the manifest is written, the
        items not done recorded ``failed`` with the reason.
    KeyboardInterrupt
        Re-raised after the pending items are cancelled, the cluster closed (or its
        start abandoned) and the manifest written (the items not done ``cancelled``).

    Examples
    --------
    >>> import tempfile
    >>> from robopercept.imaging import sample_image_path
    >>> out = Path(tempfile.mkdtemp()) / "batch"
    >>> res = run_batch("edges", [sample_image_path()], out, workers=1, progress=False)
    >>> res.count("ok"), res.items[0]["outputs"]
    (1, ['box/edges.png'])
    """
    from robopercept._checks import check_bool, check_int, check_real

    _check_job(job)
    workers = _check_workers(workers)
    retries = check_int(retries, "retries", 0)
    connect_timeout = check_real(connect_timeout, "connect_timeout", 0.0, low_inclusive=False)
    delay = check_real(delay, "delay", 0.0)
    resume = check_bool(resume, "resume")
    overwrite = check_bool(overwrite, "overwrite")
    if resume and overwrite:
        raise InputError("resume and overwrite exclude each other: give one")
    scheduler = _check_scheduler(scheduler)
    opts = _options(job, options)
    paths = find_inputs(job, inputs)
    out_path = Path(out)
    if out_path.exists() and not out_path.is_dir():
        raise InputError(f"{out_path}: exists and is not a folder: choose another output")
    if out_path.is_dir() and any(out_path.iterdir()) and not (resume or overwrite):
        raise InputError(
            f"{out_path}: exists and is not empty: give resume to finish its batch or "
            "overwrite to run every item again, or choose another output folder"
        )
    resolved_out = out_path.resolve()
    for p in paths:
        if p.resolve() == resolved_out or resolved_out in p.resolve().parents:
            raise InputError(f"{p}: an input inside the output folder {out_path}: move one")
    previous = read_manifest(out_path) if resume else None
    if previous is not None:  # checked before anything is written
        _check_resumable(previous, job, opts, out_path / MANIFEST)
    out_path.mkdir(parents=True, exist_ok=True)
    _check_log(out_path / LOG)
    earlier = {(r["item"], r["input"]): r for r in (previous or {}).get("items", [])}
    records: list[dict[str, Any]] = []
    for name, p in zip(item_names(paths), paths, strict=True):
        old = earlier.get((name, str(p)))
        if old is not None and _done(old, out_path):
            kept = {k: old[k] for k in ("attempts", "seconds", "worker", "summary") if k in old}
            records.append(
                {
                    "item": name,
                    "input": str(p),
                    "status": "skipped",
                    "attempts": 0,
                    "seconds": None,
                    "worker": "",
                    **kept,
                    "error": "",
                    "outputs": list(old["outputs"]),
                }
            )
        else:
            records.append(
                {
                    "item": name,
                    "input": str(p),
                    "status": "pending",
                    "attempts": 0,
                    "seconds": None,
                    "worker": "",
                    "error": "",
                    "outputs": [],
                }
            )
    t0 = time.perf_counter()
    result = BatchResult(job, out_path, scheduler, 0, 0.0, records)

    recorded_opts = _recorded(opts)

    def save() -> None:
        result.seconds = time.perf_counter() - t0
        doc = {"job": job, "options": recorded_opts, **result.to_dict()}
        doc.pop("results")
        doc["items"] = records
        atomic_write(out_path / MANIFEST, json.dumps(doc, indent=2, default=str) + "\n")

    todo = [i for i, r in enumerate(records) if r["status"] == "pending"]
    save()
    if not todo:
        return result

    def cancel_pending() -> None:
        for r in records:
            if r["status"] == "pending":
                r["status"] = "cancelled"
        save()

    env_before: dict[str, str | None] = {}
    address = (
        "the local Dask scheduler" if scheduler == "local" else f"the Dask scheduler at {scheduler}"
    )
    futures: dict[Any, int] = {}
    bar: Any = None
    # Dask's log lines (and the workers' tracebacks) go to OUT/batch.log, not the terminal;
    # logs.close() closes, in this order, the client and cluster (_connect), puts back
    # the environment, and restores the logging
    logs = contextlib.ExitStack()
    try:  # a Ctrl-C while dask loads or the cluster starts cancels every item
        import dask
        from distributed import as_completed

        from robopercept.progress import progress_bar

        logs.enter_context(_logs_to(out_path / LOG))
        _log.info(
            "robopercept batch %s started: %d items to run of %d, on %s",
            job, len(todo), len(records),
            f"{workers} local workers" if scheduler == "local" else scheduler,
        )  # fmt: skip
        worker_logs = _worker_log_config(out_path / LOG) if scheduler == "local" else {}
        # Dask's nannies write their pre-spawn variables (OMP_NUM_THREADS=1, ...) into
        # this process's environment: put back what was there when the batch ends
        spawn_keys = set(dask.config.get("distributed.nanny.pre-spawn-environ"))
        spawn_keys |= {k.rpartition(".")[2] for k in worker_logs}
        env_before = {k: os.environ.get(k) for k in spawn_keys}
        logs.callback(_restore_env, env_before)
        with dask.config.set(worker_logs):
            client, cluster = _connect(scheduler, workers, connect_timeout, logs)
    except BaseException as exc:
        cancel_pending()
        _log.info("robopercept batch %s ended before it started: %s", job, _error_text(exc))
        logs.close()
        raise

    def submit(i: int) -> None:
        r = records[i]
        r["attempts"] += 1
        fut = client.submit(
            _task, job, r["input"], str(out_path / r["item"]), opts, delay,
            key=f"robopercept-{job}-{r['item']}-{r['attempts']}-{os.urandom(4).hex()}",
            pure=False,
        )  # fmt: skip
        futures[fut] = i
        finished.add(fut)

    try:
        finished = as_completed()
        bar = progress_bar(total=len(todo), unit="item", desc=f"batch {job}", disable=not progress)
        result.workers = len(client.scheduler_info().get("workers", {})) or workers
        if cluster is None:
            _check_worker_env(client)
        for i in todo:
            submit(i)
        for fut in finished:
            i = futures.pop(fut)
            r = records[i]
            if fut.status == "finished":
                value = fut.result()
                r.update(status="ok", seconds=value["seconds"], worker=value["worker"], error="")
                r["outputs"] = [f"{r['item']}/{o}" for o in value["outputs"]]
                r["summary"] = value["summary"]
            elif fut.status == "cancelled" and _scheduler_gone(client):
                raise SchedulerGoneError(address)  # finished below
            else:
                cancelled = fut.status == "cancelled"
                error = None if cancelled else fut.exception()
                r["error"] = (
                    f"the task was cancelled by {address}" if cancelled else _error_text(error)
                )
                _log.error(
                    "%s (%s): attempt %d of %d failed: %s",
                    r["item"], r["input"], r["attempts"], retries + 1, r["error"],
                    exc_info=None if error is None else (type(error), error, _traceback(fut)),
                )  # fmt: skip
                if r["attempts"] <= retries:
                    save()
                    submit(i)  # the record stays pending; the bar waits for it
                    continue
                r.update(status="failed", outputs=[])
                _say(bar, f"batch {job}: {r['item']} ({r['input']}) failed: {r['error']}")
            save()
            bar.update(1)
            bar.set_postfix(failed=result.count("failed"))
        _log.info(
            "robopercept batch %s done in %.1f s: %s",
            job, time.perf_counter() - t0,
            ", ".join(f"{result.count(s)} {s}" for s in ("ok", "failed", "skipped")),
        )  # fmt: skip
    except BaseException as exc:
        gone = isinstance(exc, SchedulerGoneError) or (
            not isinstance(exc, KeyboardInterrupt | SystemExit | RoboperceptError)
            and _scheduler_gone(client)
        )
        if not gone:
            for fut, i in futures.items():
                fut.cancel()
                records[i]["status"] = "cancelled"
            cancel_pending()
            _log.info(
                "robopercept batch %s stopped (%s): %d items cancelled",
                job, _error_text(exc), result.count("cancelled"),
            )  # fmt: skip
            raise
        # the scheduler went away: what finished stays, the rest failed with the reason
        lost = f"SchedulerGoneError: {address} went away before the item finished"
        for r in records:
            if r["status"] == "pending":
                r.update(status="failed", error=lost, outputs=[])
        save()
        n_done = sum(r["status"] in ("ok", "skipped") for r in records)
        how = "" if isinstance(exc, SchedulerGoneError) else f" ({_error_text(exc)})"
        _log.error("robopercept batch %s: %s went away mid-batch%s", job, address, how)
        raise SchedulerGoneError(
            f"{address} went away mid-batch{how}: {n_done} of {len(records)} items done "
            f"and kept, the others recorded failed in {out_path / MANIFEST}: start the "
            "scheduler again (or use --scheduler local) and run the same command with "
            "--resume (resume=True) to finish them"
        ) from None
    finally:
        try:
            if bar is not None:
                bar.close()
        finally:
            logs.close()  # the client, the cluster, the environment, then the logging
    save()
    return result


def _traceback(fut: Any) -> Any:
    """The traceback of a failed future (None when Dask has none to give)."""
    try:
        return fut.traceback()
    except Exception:  # the log loses the traceback, the batch goes on
        return None


def _say(bar: Any, line: str) -> None:
    """Print ``line`` on stderr, above the progress ``bar`` when it is tqdm's."""
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        tqdm = None
    if tqdm is not None and isinstance(bar, tqdm):
        tqdm.write(line, file=sys.stderr)
    elif not getattr(bar, "disable", False):
        print(line, file=sys.stderr, flush=True)


def _restore_env(saved: Mapping[str, str | None]) -> None:
    """Set the variables of ``saved`` back (None: unset)."""
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
