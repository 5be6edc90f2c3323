"""``robopercept nn``: the deep-learning commands (extra ``deep``), one module per task,
as the command line reads: ``nn train|eval|predict|summary`` (:mod:`.classify`),
``nn detect`` (:mod:`.detect`), ``nn segment`` (:mod:`.segment`), ``nn pose``
(:mod:`.pose`), ``nn cloud`` (:mod:`.cloud`) and ``nn models`` (:mod:`.models`, the
shipped models' cards); :mod:`._forms` holds what the task
commands share (their three forms ``train``, ``eval`` and ``IMAGE...``, the data flags).

These modules parse and print. From :mod:`robopercept.nn` they import only the task
wings' ``run`` modules, the predictor (:mod:`robopercept.nn.predict`) and the
shipped-model table (:mod:`robopercept.nn.shipped`), and only when a command runs, so
the parser stays torch-free (``tests/test_architecture.py`` checks both).
"""

from __future__ import annotations

import argparse

from robopercept.cli.nn import classify, cloud, detect, models, pose, segment

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``nn`` and its tasks to the subcommand parsers ``sub``."""
    p = sub.add_parser(
        "nn",
        help="neural networks: image classifiers, detectors, segmenters, pose and "
        "point-cloud networks; train, evaluate, predict (needs torch)",
        description="Neural networks in PyTorch (extra deep: pip install "
        "'robopercept[deep]'): small VGG, Inception and ResNet image classifiers (train, "
        "eval, predict, summary), object detectors (detect), semantic and instance "
        "segmentation (segment), human pose (pose) and point-cloud networks (cloud), each "
        "with shipped models (models lists them). Run a TASK with --help for its options.",
    )
    ns = p.add_subparsers(dest="nn_command", metavar="TASK", parser_class=type(p))
    ns.required = True
    classify.register(ns)
    models.register(ns)
    for task in (detect, segment, pose, cloud):
        task.register(ns, type(p))
