"""Backends behind `map_chunks`: local processes (joblib/loky), Dask, Ray.

Why coarse chunks: the per-item work (a value iteration over a few hundred states) is far
cheaper than shipping a task, so callers group items into chunks and the backend only ever
sees a handful of tasks per worker. Why seeds by chunk index: the random stream a chunk
sees must not depend on which worker runs it, or how many workers there are.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")
R = TypeVar("R")

BACKENDS = ("local", "dask", "ray")

SeedLike = int | np.random.SeedSequence | None


class BackendUnavailableError(RuntimeError):
    """The chosen backend's optional dependency is not installed."""


@dataclass(frozen=True)
class ParallelConfig:
    """Where chunks run: `backend` (local, dask, ray), `n_workers` (None: all cores for
    local, the cluster's own size for a given Dask/Ray address) and `scheduler` (a Dask
    scheduler address like ``tcp://host:8786`` or a Ray address like ``ray://host:10001``;
    None starts a local cluster)."""

    backend: str = "local"
    n_workers: int | None = None
    scheduler: str | None = None

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ValueError(
                f"unknown parallel backend {self.backend!r}; choose one of {', '.join(BACKENDS)}"
            )
        if self.n_workers is not None:
            if isinstance(self.n_workers, bool) or not isinstance(self.n_workers, int):
                raise TypeError(f"n_workers must be an int or None, got {self.n_workers!r}")
            if self.n_workers < 1:
                raise ValueError(f"n_workers must be at least 1, got {self.n_workers}")
        if self.scheduler is not None and self.backend == "local":
            raise ValueError(
                "a scheduler address only makes sense with backend 'dask' or 'ray', "
                f"not 'local' (got scheduler={self.scheduler!r})"
            )


def spawn_seeds(seed: SeedLike, n: int) -> list[np.random.SeedSequence]:
    """The `n` child seed sequences of `seed`, child `i` for chunk `i`.

    Stateless (unlike `SeedSequence.spawn`, which counts earlier calls): the same `seed`
    always gives the same children, so re-running a sweep reproduces it.
    """
    if n < 0:
        raise ValueError(f"cannot spawn a negative number of seeds ({n})")
    if isinstance(seed, np.random.SeedSequence):
        root = seed
    elif seed is None or (isinstance(seed, int | np.integer) and not isinstance(seed, bool)):
        if seed is not None and seed < 0:
            raise ValueError(f"seed must be a non-negative int, got {seed}")
        root = np.random.SeedSequence(seed)
    else:
        raise TypeError(f"seed must be an int, a numpy SeedSequence or None, got {seed!r}")
    return [
        np.random.SeedSequence(
            entropy=root.entropy, spawn_key=(*root.spawn_key, i), pool_size=root.pool_size
        )
        for i in range(n)
    ]


def chunk_slices(n_items: int, *, n_chunks: int | None = None,
                 chunk_size: int | None = None) -> list[slice]:
    """Contiguous, balanced slices covering `range(n_items)`.

    Give exactly one of `n_chunks` or `chunk_size`. When the work is random, derive the
    chunking from the problem (e.g. a fixed `chunk_size`), never from the worker count:
    the seeds follow the chunks.
    """
    if (n_chunks is None) == (chunk_size is None):
        raise ValueError("give exactly one of n_chunks or chunk_size")
    if n_items < 0:
        raise ValueError(f"n_items must be non-negative, got {n_items}")
    if n_items == 0:
        return []
    if chunk_size is not None:
        if chunk_size < 1:
            raise ValueError(f"chunk_size must be at least 1, got {chunk_size}")
        n_chunks = -(-n_items // chunk_size)
    assert n_chunks is not None
    if n_chunks < 1:
        raise ValueError(f"n_chunks must be at least 1, got {n_chunks}")
    n_chunks = min(n_chunks, n_items)
    bounds = np.linspace(0, n_items, n_chunks + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def chunked(items: Sequence[T] | np.ndarray, *, n_chunks: int | None = None,
            chunk_size: int | None = None) -> list[Any]:
    """Split a sequence (list, tuple, numpy array along axis 0) into contiguous chunks."""
    return [items[s] for s in chunk_slices(len(items), n_chunks=n_chunks, chunk_size=chunk_size)]


def _call(fn: Callable[..., R], chunk: Any, seed: np.random.SeedSequence | None) -> R:
    """Run one chunk; module-level so every backend can pickle it."""
    return fn(chunk) if seed is None else fn(chunk, seed)


def _progress_bar(total: int, enabled: bool, desc: str | None):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, file=sys.stderr,
                disable=not (enabled and sys.stderr.isatty()))


class Executor:
    """A reusable handle on one backend; keeps a Dask client or Ray session open across
    many `map` calls (starting a cluster costs seconds). Use as a context manager."""

    def __init__(self, config: ParallelConfig | None = None, *, backend: str | None = None,
                 n_workers: int | None = None, scheduler: str | None = None) -> None:
        if config is None:
            config = ParallelConfig(backend=backend or "local", n_workers=n_workers,
                                    scheduler=scheduler)
        elif backend is not None or n_workers is not None or scheduler is not None:
            raise ValueError("give either a ParallelConfig or backend/n_workers/scheduler")
        self.config = config
        self._client: Any = None
        self._cluster: Any = None
        self._ray_started = False

    # -- lifecycle -------------------------------------------------------------------
    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Shut down whatever this executor started (never a cluster it only joined)."""
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None
        if self._ray_started:
            import ray

            ray.shutdown()
            self._ray_started = False

    @property
    def n_workers(self) -> int:
        """How many workers chunks can run on at once."""
        if self.config.backend == "local":
            if self.config.n_workers is not None:
                return self.config.n_workers
            import joblib

            return max(1, joblib.cpu_count())
        if self.config.backend == "dask":
            client = self._dask_client()
            return max(1, sum(w["nthreads"] for w in client.scheduler_info()["workers"].values()))
        self._ray_init()
        import ray

        return max(1, int(ray.cluster_resources().get("CPU", 1)))

    # -- mapping ---------------------------------------------------------------------
    def map(self, fn: Callable[..., R], chunks: Sequence[Any], *, seed: SeedLike = None,
            progress: bool = False, desc: str | None = None) -> list[R]:
        """`[fn(chunk_i)]` or, with a seed, `[fn(chunk_i, seed_i)]`, in chunk order.

        `seed_i` is the `i`-th child `SeedSequence` of `seed` (`spawn_seeds`), so
        `np.random.default_rng(seed_i)` gives the same stream on every backend.
        """
        chunks = list(chunks)
        seeds: list[np.random.SeedSequence | None]
        seeds = [None] * len(chunks) if seed is None else list(spawn_seeds(seed, len(chunks)))
        if not chunks:
            return []
        runner = {"local": self._map_local, "dask": self._map_dask, "ray": self._map_ray}
        return runner[self.config.backend](fn, chunks, seeds, progress, desc)

    def _map_local(self, fn, chunks, seeds, progress, desc):
        n_jobs = min(self.n_workers, len(chunks))
        pairs = zip(chunks, seeds, strict=True)
        with _progress_bar(len(chunks), progress, desc) as bar:
            if n_jobs == 1:
                gen = (_call(fn, c, s) for c, s in pairs)
            else:
                from joblib import Parallel, delayed

                gen = Parallel(n_jobs=n_jobs, backend="loky", return_as="generator")(
                    delayed(_call)(fn, c, s) for c, s in pairs
                )
            out = []
            for r in gen:
                out.append(r)
                bar.update()
            return out

    def _dask_client(self):
        if self._client is not None:
            return self._client
        try:
            from distributed import Client, LocalCluster
        except ImportError as err:  # pragma: no cover - dask is in the dev extra
            raise BackendUnavailableError(
                "the dask backend needs the dask extra: pip install 'cfteach[dask]'"
            ) from err
        if self.config.scheduler is not None:
            try:
                self._client = Client(self.config.scheduler, timeout="10s")
            except OSError as err:
                raise ConnectionError(
                    f"cannot reach the Dask scheduler at {self.config.scheduler!r}: {err}"
                ) from err
        else:
            import dask
            import joblib

            n = self.config.n_workers or max(1, joblib.cpu_count())
            # The workers' statistical profiler samples every thread's stack every 10 ms,
            # and Dask's default MALLOC_TRIM_THRESHOLD_ turns off glibc's adaptive mmap
            # threshold, so every large numpy temporary is a fresh mmap with page faults:
            # for long numpy chunks both are pure overhead.
            with dask.config.set({"distributed.worker.profile.enabled": False,
                                  "distributed.nanny.pre-spawn-environ."
                                  "MALLOC_TRIM_THRESHOLD_": None}):
                self._cluster = LocalCluster(n_workers=n, threads_per_worker=1,
                                             processes=True, dashboard_address=None,
                                             silence_logs=logging.ERROR)
            self._client = Client(self._cluster)
        return self._client

    def _map_dask(self, fn, chunks, seeds, progress, desc):
        from distributed import as_completed

        client = self._dask_client()
        futures = [client.submit(_call, fn, c, s, pure=False)
                   for c, s in zip(chunks, seeds, strict=True)]
        try:
            with _progress_bar(len(chunks), progress, desc) as bar:
                for _ in as_completed(futures):
                    bar.update()
            return client.gather(futures)
        finally:
            for f in futures:
                f.release()

    def _ray_init(self) -> None:
        try:
            import ray
        except ImportError as err:
            raise BackendUnavailableError(
                "the ray backend needs the ray extra: pip install 'cfteach[ray]'"
            ) from err
        if not ray.is_initialized():
            kwargs: dict[str, Any] = {"ignore_reinit_error": True, "log_to_driver": False}
            if self.config.scheduler is not None:
                kwargs["address"] = self.config.scheduler
            elif self.config.n_workers is not None:
                kwargs["num_cpus"] = self.config.n_workers
            ray.init(**kwargs)
            self._ray_started = True

    def _map_ray(self, fn, chunks, seeds, progress, desc):
        self._ray_init()
        import ray

        remote = ray.remote(num_cpus=1)(_call)
        fn_ref = ray.put(fn)
        refs = [remote.remote(fn_ref, c, s) for c, s in zip(chunks, seeds, strict=True)]
        pending = list(refs)
        with _progress_bar(len(chunks), progress, desc) as bar:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                bar.update(len(done))
        return ray.get(refs)


def map_chunks(fn: Callable[..., R], chunks: Sequence[Any], *, backend: str = "local",
               n_workers: int | None = None, scheduler: str | None = None,
               seed: SeedLike = None, progress: bool = False, desc: str | None = None,
               executor: Executor | None = None) -> list[R]:
    """Map `fn` over `chunks` on a backend; results in chunk order.

    Without `seed`, `fn(chunk)` is called; with one, `fn(chunk, seed_i)` where `seed_i` is
    chunk `i`'s child `numpy.random.SeedSequence`. `fn` must be picklable by cloudpickle
    (module-level functions and `functools.partial` of them are safest). Pass a live
    `executor` to reuse its workers across calls; otherwise one is started and closed here.
    """
    if executor is not None:
        if backend != "local" or n_workers is not None or scheduler is not None:
            raise ValueError("give either an executor or backend/n_workers/scheduler")
        return executor.map(fn, chunks, seed=seed, progress=progress, desc=desc)
    with Executor(backend=backend, n_workers=n_workers, scheduler=scheduler) as ex:
        return ex.map(fn, chunks, seed=seed, progress=progress, desc=desc)
