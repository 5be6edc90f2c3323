"""Data-parallel training on several processes: torch DistributedDataParallel (DDP).

:func:`run_ranks` calls a function on ``nproc`` processes of this machine (started with
:func:`torch.multiprocessing.start_processes`) joined in a ``torch.distributed`` process
group, or, when the process was started by ``torchrun`` (the environment holds ``RANK``,
``WORLD_SIZE``, ``LOCAL_RANK``, ``MASTER_ADDR`` and ``MASTER_PORT``,
:func:`torchrun_env`), as the rank torchrun made, which is how a run spans machines::

    torchrun --no-python --nnodes 2 --nproc-per-node 1 --rdzv-backend c10d \\
        --rdzv-endpoint HOST:PORT robopercept nn train --data digits ...

``nn train --nproc N`` is :func:`robopercept.nn.classification.run.train_ddp`, which
runs its trainer through :func:`run_ranks`. Every rank builds the same model (same
seed) and joins a process group (backend gloo on the CPU, nccl when the device is CUDA:
:func:`rank_device`); :func:`~robopercept.nn.train.fit.fit` wraps the model in
:class:`~torch.nn.parallel.DistributedDataParallel`, swaps its batch norms for
:class:`SyncBatchNorm` (statistics of the global batch), and every rank draws the global
batches of one process (the same seeded shuffle) and runs its share of each.

The global batch stays the one asked for: each of the N processes takes
``batch_size / N`` images per step and DDP averages the gradients, so one step sees
``batch_size`` images as on one process, and the learning rate is left unchanged (the
learning rate scales linearly with the global batch, which does not change). The batch
size must therefore be a multiple of N (:func:`check_world_batch`). Batch norm takes the
global batch's statistics (:class:`SyncBatchNorm`), so runs on 1 and N processes of a
model without dropout agree to float rounding (``nn train --per-process-bn`` keeps each
process's own statistics, torch DDP's default).

Rank 0 alone validates, evaluates the test split and writes the run folder (checkpoints,
history, curves, metrics, confusion matrix); the other ranks wait for it. The process
group is destroyed on the way out, error or not; an error or Ctrl-C on one rank stops
them all (here the other processes are terminated; torchrun does the same for its
workers) and the error is raised again in the launching process. A rank started here
takes SIGTERM (how the launcher stops it, also when the launcher itself is stopped by
Ctrl-C or SIGTERM) as Ctrl-C: its trainer's cleanup runs, so an interrupted ``nn train
--nproc N`` keeps the same files as one process does.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import os
import pickle
import signal
import socket
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from robopercept._checks import check_bool, check_choice, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_device, check_float_dtype
from robopercept.nn.train.config import TrainConfig

__all__ = [
    "SyncBatchNorm",
    "check_world_batch",
    "free_port",
    "rank_device",
    "run_ranks",
    "sync_batchnorm",
    "torchrun_env",
]

#: the environment variables torchrun sets for each worker (all of them: a torchrun run)
TORCHRUN_VARIABLES = ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT")


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` now (the operating system's pick): ``MASTER_PORT`` of a
    run started here when none is given.

    Raises
    ------
    InputError
        ``host`` is not a name or address of this machine.

    Examples
    --------
    >>> 0 < free_port() < 65536
    True
    """
    if not isinstance(host, str) or not host:
        raise InputError(f"host must be a host name or address; got {plain_repr(host)}")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, 0))
        except OSError as exc:  # an unknown name (socket.gaierror) or a foreign address
            raise InputError(
                f"cannot bind a port on host {host!r} ({exc}); give this machine's name or "
                "address (MASTER_ADDR), e.g. 127.0.0.1"
            ) from None
        return int(s.getsockname()[1])


def torchrun_env(environ: dict[str, str] | None = None) -> tuple[int, int, int] | None:
    """``(rank, world_size, local_rank)`` when this process was started by ``torchrun``
    (every one of ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK``, ``MASTER_ADDR``,
    ``MASTER_PORT`` set), else None.

    Parameters
    ----------
    environ : dict, optional
        The environment to read (default ``os.environ``).

    Raises
    ------
    InputError
        The variables are set but not integers with 0 <= rank < world size.

    Examples
    --------
    >>> torchrun_env({})
    >>> env = {"RANK": "1", "WORLD_SIZE": "2", "LOCAL_RANK": "0",
    ...        "MASTER_ADDR": "10.0.0.1", "MASTER_PORT": "29500"}
    >>> torchrun_env(env)
    (1, 2, 0)
    """
    env = os.environ if environ is None else environ
    if not isinstance(env, (dict, type(os.environ))):
        raise InputError(f"environ must be a dict of str; got {plain_repr(environ)}")
    if not all(k in env for k in TORCHRUN_VARIABLES):
        return None
    try:
        rank, world, local = (int(env[k]) for k in ("RANK", "WORLD_SIZE", "LOCAL_RANK"))
    except (TypeError, ValueError):
        raise InputError(
            "RANK, WORLD_SIZE and LOCAL_RANK must be integers (set by torchrun); got "
            f"{[env[k] for k in ('RANK', 'WORLD_SIZE', 'LOCAL_RANK')]}"
        ) from None
    if not (0 <= rank < world and local >= 0):
        raise InputError(f"RANK {rank} must be in 0..WORLD_SIZE-1 (WORLD_SIZE {world})")
    return rank, world, local


def check_world_batch(nproc: int, batch_size: int) -> None:
    """Refuse a global batch that ``nproc`` processes cannot share out evenly: each
    process takes ``batch_size / nproc`` images per step.

    Parameters
    ----------
    nproc : int
        Processes of the run (>= 1).
    batch_size : int
        The global batch (>= 1).

    Raises
    ------
    InputError
        ``nproc`` larger than ``batch_size`` or not dividing it (the message names the
        nearest batch sizes that work).

    Examples
    --------
    >>> check_world_batch(2, 64)
    >>> check_world_batch(2, 63)
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: --batch-size 63 (the global batch) must be a multiple of ...
    """
    nproc = check_int(nproc, "nproc (--nproc)", 1)
    batch_size = check_int(batch_size, "batch_size (--batch-size)", 1)
    if nproc > batch_size:
        raise InputError(
            f"--nproc {nproc} is larger than --batch-size {batch_size} (the global batch, "
            f"shared out among the processes): use at most --nproc {batch_size}"
        )
    if batch_size % nproc:
        lower = batch_size - batch_size % nproc
        raise InputError(
            f"--batch-size {batch_size} (the global batch) must be a multiple of --nproc "
            f"{nproc}: each process takes batch_size / nproc images; use --batch-size "
            f"{lower} or {lower + nproc}"
        )


def rank_device(cfg: TrainConfig) -> tuple[TrainConfig, str]:
    """The configuration of this rank (its device set to its own CUDA device, number
    ``LOCAL_RANK``, when the run is on CUDA) and the process-group backend: nccl on
    CUDA, else gloo.

    Parameters
    ----------
    cfg : TrainConfig

    Returns
    -------
    cfg : TrainConfig
        ``cfg`` itself off CUDA, else a copy with ``device="cuda:<index>"``.
    backend : {'gloo', 'nccl'}

    Raises
    ------
    InputError
        ``cfg`` is not a TrainConfig.

    Examples
    --------
    >>> rank_device(TrainConfig(device="cpu"))[1]
    'gloo'
    """
    if not isinstance(cfg, TrainConfig):
        raise InputError(f"cfg must be a TrainConfig; got {plain_repr(cfg)}")
    name = cfg.device
    if name is None:
        name = "cuda" if torch.cuda.is_available() else "cpu"
    dev = torch.device(name)
    if dev.type != "cuda":
        return cfg, "gloo"
    index = int(os.environ.get("LOCAL_RANK", 0)) if dev.index is None else dev.index
    return dataclasses.replace(cfg, device=f"cuda:{index}"), "nccl"


def _rank_main(
    local_rank: int, fn: Callable[..., Any], args: tuple[Any, ...], job: dict[str, Any]
) -> Any:
    """One process: join the process group, call ``fn(*args)``, leave the group (error
    or not). Rank 0 stores the result, a failing rank its error, for the launcher."""
    import torch.distributed as dist

    torch.set_num_threads(job["threads"])
    if job["spawned"]:
        # the launcher stops its ranks with SIGTERM (run_ranks, on an error, Ctrl-C or
        # its own SIGTERM): raise KeyboardInterrupt as Ctrl-C does, so the trainer's
        # cleanup runs (rank 0 writes the interrupted run's history) instead of dying
        signal.signal(signal.SIGTERM, signal.default_int_handler)
        os.environ["LOCAL_RANK"] = str(local_rank)
        rank, world = local_rank, job["nproc"]
        init = f"tcp://{job['addr']}:{job['port']}"
    else:
        rank, world = job["rank"], job["world"]
        init = "env://"
    try:
        if job["backend"] == "nccl":
            torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", 0)))
        dist.init_process_group(
            job["backend"],
            init_method=init,
            rank=rank,
            world_size=world,
            timeout=datetime.timedelta(seconds=job["timeout"]),
        )
        res = fn(*args)
        dist.barrier()  # every rank done before any leaves (gloo aborts on a peer gone early)
        if rank == 0 and job["result"] is not None:
            Path(job["result"]).write_bytes(pickle.dumps(res))
        return res
    except BaseException as exc:
        if job["errors"] is not None:  # the launcher raises the first rank's error again
            with contextlib.suppress(Exception):
                Path(job["errors"], f"{rank}.pkl").write_bytes(pickle.dumps((time.time_ns(), exc)))
        raise
    finally:
        if dist.is_initialized():
            dist.destroy_process_group()


def run_ranks(
    fn: Callable[..., Any],
    nproc: int,
    args: tuple[Any, ...] = (),
    *,
    backend: str = "gloo",
    threads: int | None = None,
    timeout: float = 1800.0,
) -> Any:
    """Call ``fn(*args)`` in ``nproc`` new processes of this machine joined in a
    ``torch.distributed`` process group (or, under torchrun, in this process as its
    rank); return rank 0's return value.

    The processes are started with the spawn method (``fn``, ``args`` and the result
    must pickle; ``fn`` a module-level function). ``MASTER_ADDR`` and ``MASTER_PORT`` are
    taken from the environment when set, else 127.0.0.1 and a :func:`free_port`. The
    first rank to fail stops the run: the others are terminated, every process is
    joined, and its exception is raised here. Each process destroys its process group on
    the way out.

    Parameters
    ----------
    fn : callable
        Runs on every rank (``torch.distributed.get_rank()`` tells which).
    nproc : int
        Processes (>= 1); must be 1 under torchrun (torchrun's processes are the ranks).
    args : tuple
        ``fn``'s arguments.
    backend : {'gloo', 'nccl'}
    threads : int, optional
        torch threads per process (default: torch's thread count / processes, >= 1).
    timeout : float
        Seconds a collective waits for the other ranks.

    Returns
    -------
    object
        Rank 0's ``fn(*args)``.

    Raises
    ------
    InputError
        Bad ``nproc``, ``backend``, ``threads`` or ``timeout``; ``nproc`` > 1 under torchrun.
    Exception
        The first failing rank's exception (its class and message; or torch's
        ProcessRaisedException / ProcessExitedException when it cannot be carried).

    Examples
    --------
    >>> run_ranks(print, 0)
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: nproc (--nproc) must be >= 1; got 0
    """
    if not callable(fn):
        raise InputError(f"fn must be a module-level function; got {plain_repr(fn)}")
    nproc = check_int(nproc, "nproc (--nproc)", 1)
    if not isinstance(args, tuple):
        raise InputError(f"args must be a tuple; got {plain_repr(args)}")
    backend = check_choice(backend, "backend", ("gloo", "nccl"))
    timeout = check_real(timeout, "timeout (seconds)", 0.0, low_inclusive=False)
    if threads is not None:
        threads = check_int(threads, "threads", 1)
    env = torchrun_env()
    if env is not None and nproc != 1:
        raise InputError(
            f"--nproc {nproc} under torchrun: torchrun starts the processes "
            "(--nproc-per-node); leave --nproc at 1"
        )
    local = int(os.environ.get("LOCAL_WORLD_SIZE", 1)) if env is not None else nproc
    job: dict[str, Any] = {
        "backend": backend,
        "threads": threads or max(1, torch.get_num_threads() // max(1, local)),
        "timeout": timeout,
        "nproc": nproc,
        "spawned": env is None,
        "result": None,
        "errors": None,
    }
    if env is not None:  # this process is one rank
        job.update(rank=env[0], world=env[1])
        return _rank_main(env[2], fn, args, job)
    return _spawn(fn, args, job)


def _spawn(fn: Callable[..., Any], args: tuple[Any, ...], job: dict[str, Any]) -> Any:
    """Start the ranks, wait for them, terminate them all on the first failure."""
    import torch.multiprocessing as mp

    job["addr"] = os.environ.get("MASTER_ADDR", "127.0.0.1")
    job["port"] = int(os.environ.get("MASTER_PORT", 0)) or free_port(job["addr"])
    with tempfile.TemporaryDirectory(prefix="robopercept-ddp-") as tmp:
        job["result"] = os.path.join(tmp, "result.pkl")
        job["errors"] = tmp
        ctx = mp.start_processes(
            _rank_main, args=(fn, args, job), nprocs=job["nproc"], join=False, start_method="spawn"
        )
        try:
            while not ctx.join():
                pass
        except mp.ProcessRaisedException:
            # the first error written is the cause (a rank that fails leaves the group,
            # so the others' collectives fail after it: "connection closed by peer")
            errors = sorted(pickle.loads(f.read_bytes()) for f in Path(tmp).glob("[0-9]*.pkl"))
            if errors:
                raise errors[0][1] from None
            raise
        finally:
            for p in ctx.processes:
                if p.is_alive():
                    p.terminate()
            for p in ctx.processes:
                p.join(10)
                if p.is_alive():
                    p.kill()
                    p.join()
        return pickle.loads(Path(job["result"]).read_bytes())


# ------------------------------------------------------------------ batch norm
class SyncBatchNorm(torch.nn.modules.batchnorm._BatchNorm):
    r"""Batch normalization whose training statistics are those of the *global* batch
    (every process's share together), on any device: the CPU processes of ``nn train
    --nproc N`` (gloo) as well as GPUs. Torch's own ``SyncBatchNorm`` refuses CPU
    tensors.

    In training, each process sums its share, :math:`s = \sum x`, :math:`q = \sum x^2`
    and the count :math:`n` per channel; an all-reduce
    (``torch.distributed.nn.functional.all_reduce``, which carries the gradient back
    through the sum) gives the global :math:`S, Q, N`, then
    :math:`\mu = S / N`, :math:`\sigma^2 = Q / N - \mu^2` (biased, as BatchNorm
    normalizes) and :math:`y = \gamma (x - \mu) / \sqrt{\sigma^2 + \epsilon} + \beta`.
    The running variance takes the unbiased :math:`\sigma^2 N / (N - 1)`, as
    ``torch.nn.BatchNorm`` does. Without an initialized process group, or in eval mode,
    it is a plain batch norm. The state-dict keys are BatchNorm's.

    Examples
    --------
    >>> bn = SyncBatchNorm(3)
    >>> x = torch.randn(4, 3, 5, 5)
    >>> ref = torch.nn.BatchNorm2d(3)
    >>> bool(torch.allclose(bn(x), ref(x), atol=1e-6))  # one process: BatchNorm2d
    True
    """

    def __init__(
        self,
        num_features: int,
        eps: float = 1e-5,
        momentum: float | None = 0.1,
        affine: bool = True,
        track_running_stats: bool = True,
        device: Any = None,
        dtype: Any = None,
    ) -> None:
        """As :class:`torch.nn.BatchNorm2d`'s, each argument checked: ``num_features``
        in 1 .. 65536, ``eps`` > 0, ``momentum`` in [0, 1] or None, a device this machine
        has and a floating-point dtype (:class:`InputError` otherwise)."""
        n = check_count(num_features, "num_features", 1, 2**16)
        e = check_real(eps, "eps", 0.0, 1.0, low_inclusive=False)
        m = None if momentum is None else check_real(momentum, "momentum", 0.0, 1.0)
        a = check_bool(affine, "affine")
        t = check_bool(track_running_stats, "track_running_stats")
        dev = check_device(device)
        dt = None if dtype is None else check_float_dtype(dtype)
        super().__init__(n, e, m, a, t, device=dev, dtype=dt)  # type: ignore[arg-type]

    def _check_input_dim(self, input: torch.Tensor) -> None:
        if input.dim() < 2:
            raise InputError(f"SyncBatchNorm expects (N, C, ...) input; got {tuple(input.shape)}")

    def forward(self, input: torch.Tensor) -> torch.Tensor:
        import torch.distributed as dist

        self._check_input_dim(input)
        if not (self.training and dist.is_available() and dist.is_initialized()):
            return super().forward(input)
        from torch.distributed.nn.functional import all_reduce

        dims = [0, *range(2, input.dim())]
        x = input.float()
        n_local = x.numel() // x.shape[1]
        stats = torch.cat(
            [
                x.sum(dims),
                (x * x).sum(dims),
                torch.full((1,), float(n_local), dtype=x.dtype, device=x.device),
            ]
        )
        total = all_reduce(stats)
        c = x.shape[1]
        n = total[2 * c]
        mean = total[:c] / n
        var = (total[c : 2 * c] / n - mean * mean).clamp_min(0)
        shape = [1, c] + [1] * (input.dim() - 2)
        y = (x - mean.view(shape)) / torch.sqrt(var.view(shape) + self.eps)
        if self.affine:
            y = y * self.weight.view(shape) + self.bias.view(shape)
        if self.track_running_stats and self.running_mean is not None:
            with torch.no_grad():
                assert self.running_var is not None and self.num_batches_tracked is not None
                self.num_batches_tracked.add_(1)
                m = (
                    1.0 / float(self.num_batches_tracked)
                    if self.momentum is None
                    else float(self.momentum)
                )
                unbiased = var * n / (n - 1).clamp_min(1)
                self.running_mean.mul_(1 - m).add_(mean.detach(), alpha=m)
                self.running_var.mul_(1 - m).add_(unbiased.detach(), alpha=m)
        return y.to(input.dtype)


def sync_batchnorm(model: torch.nn.Module) -> Callable[[], None]:
    """Replace every batch-norm layer of ``model`` (in place) by a :class:`SyncBatchNorm`
    sharing its parameters and statistics (the same tensors); return the function that
    puts the original layers back, trained (what
    :func:`~robopercept.nn.train.fit.fit` does around a distributed run).

    Examples
    --------
    >>> net = torch.nn.Sequential(torch.nn.Conv2d(1, 2, 3), torch.nn.BatchNorm2d(2))
    >>> undo = sync_batchnorm(net)
    >>> type(net[1]).__name__
    'SyncBatchNorm'
    >>> undo()
    >>> type(net[1]).__name__
    'BatchNorm2d'
    """
    if not isinstance(model, torch.nn.Module):
        raise InputError(f"model must be a torch.nn.Module; got {plain_repr(model)}")
    swapped: list[tuple[torch.nn.Module, str, torch.nn.Module, torch.nn.Module]] = []
    for parent in list(model.modules()):
        for name, child in list(parent.named_children()):
            if isinstance(child, torch.nn.modules.batchnorm._BatchNorm) and not isinstance(
                child, SyncBatchNorm
            ):
                sync = SyncBatchNorm(
                    child.num_features,
                    child.eps,
                    child.momentum,  # type: ignore[arg-type]
                    child.affine,
                    child.track_running_stats,
                )
                # the very same parameters and buffers (updated in place): the optimizer
                # and the original layer see every step
                for key in ("weight", "bias"):
                    if getattr(child, key, None) is not None:
                        setattr(sync, key, getattr(child, key))
                for key in ("running_mean", "running_var", "num_batches_tracked"):
                    sync._buffers[key] = child._buffers.get(key)
                sync.train(child.training)
                setattr(parent, name, sync)
                swapped.append((parent, name, child, sync))

    def undo() -> None:
        for parent, name, child, sync in swapped:
            child.train(sync.training)
            setattr(parent, name, child)

    return undo
