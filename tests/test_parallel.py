"""cfteach.parallel: same seeded results on every backend and worker count; clear errors."""

from __future__ import annotations

import functools
import importlib.util
import os

import numpy as np
import pytest

from cfteach import parallel
from cfteach.parallel import (
    BackendUnavailableError,
    Executor,
    ParallelConfig,
    chunk_slices,
    chunked,
    map_chunks,
    spawn_seeds,
)


def _draw(chunk: np.ndarray, seed: np.random.SeedSequence) -> np.ndarray:
    """Random work that depends on the chunk's data and its seed."""
    rng = np.random.default_rng(seed)
    return chunk * rng.standard_normal(len(chunk)) + rng.integers(0, 1000, len(chunk))


def _square(chunk: list[int]) -> list[int]:
    return [x * x for x in chunk]


def _pid(_chunk: object) -> int:
    return os.getpid()


def _fail_on(chunk: list[int], bad: int) -> list[int]:
    if bad in chunk:
        raise ArithmeticError(f"chunk holding {bad}")
    return chunk


def _expected_draw(data: np.ndarray, seed: int, chunk_size: int) -> np.ndarray:
    """Independent computation: spawn with numpy's own API, draw serially."""
    root = np.random.SeedSequence(seed)
    out = []
    for i, child in enumerate(root.spawn(-(-len(data) // chunk_size))):
        piece = data[i * chunk_size:(i + 1) * chunk_size]
        rng = np.random.default_rng(child)
        out.append(piece * rng.standard_normal(len(piece)) + rng.integers(0, 1000, len(piece)))
    return np.concatenate(out)


DATA = np.arange(1.0, 41.0)


def test_seeded_results_match_numpy_spawn_on_one_worker() -> None:
    got = map_chunks(_draw, chunked(DATA, chunk_size=8), n_workers=1, seed=7)
    np.testing.assert_array_equal(np.concatenate(got), _expected_draw(DATA, 7, 8))


def test_local_two_workers_equals_one_worker_and_uses_other_processes() -> None:
    chunks = chunked(DATA, chunk_size=8)
    one = map_chunks(_draw, chunks, n_workers=1, seed=11)
    two = map_chunks(_draw, chunks, n_workers=2, seed=11)
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a, b)
    pids = map_chunks(_pid, [0, 1, 2, 3], n_workers=2)
    assert os.getpid() not in pids


@pytest.mark.slow
def test_dask_local_cluster_equals_local() -> None:
    chunks = chunked(DATA, chunk_size=8)
    local = map_chunks(_draw, chunks, n_workers=1, seed=3)
    with Executor(backend="dask", n_workers=2) as ex:
        assert ex.n_workers == 2
        dask_out = ex.map(_draw, chunks, seed=3)
        # The executor keeps its cluster: a second call reuses it and gives the same answer.
        again = ex.map(_draw, chunks, seed=3)
        # Exceptions inside tasks reach the caller.
        with pytest.raises(ArithmeticError, match="chunk holding 5"):
            ex.map(functools.partial(_fail_on, bad=5), [[1, 2], [5, 6]])
    for a, b, c in zip(local, dask_out, again, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_results_come_back_in_chunk_order() -> None:
    chunks = [list(range(i, i + 3)) for i in range(0, 30, 3)]
    got = map_chunks(_square, chunks, n_workers=2)
    assert [x for c in got for x in c] == [x * x for x in range(30)]


def test_different_seeds_differ_and_no_seed_means_one_argument() -> None:
    chunks = chunked(DATA, n_chunks=2)
    a = np.concatenate(map_chunks(_draw, chunks, n_workers=1, seed=1))
    b = np.concatenate(map_chunks(_draw, chunks, n_workers=1, seed=2))
    assert not np.array_equal(a, b)
    with pytest.raises(TypeError):
        map_chunks(_draw, chunks, n_workers=1)  # fn needs a seed but none was given


def test_spawn_seeds_is_stateless_and_matches_numpy_spawn() -> None:
    ss = np.random.SeedSequence(5)
    first = spawn_seeds(ss, 4)
    second = spawn_seeds(ss, 4)
    reference = np.random.SeedSequence(5).spawn(4)
    for x, y, z in zip(first, second, reference, strict=True):
        np.testing.assert_array_equal(x.generate_state(4), y.generate_state(4))
        np.testing.assert_array_equal(x.generate_state(4), z.generate_state(4))
    with pytest.raises(TypeError, match="seed must be"):
        spawn_seeds("abc", 2)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="non-negative"):
        spawn_seeds(-1, 2)


def test_chunk_slices_cover_everything_once() -> None:
    for n in (0, 1, 7, 64, 101):
        for k in (1, 3, 8, 200):
            slices = chunk_slices(n, n_chunks=k)
            covered = [i for s in slices for i in range(n)[s]]
            assert covered == list(range(n))
            if n:
                sizes = [s.stop - s.start for s in slices]
                assert len(slices) == min(k, n) and max(sizes) - min(sizes) <= 1
    for n, size in ((10, 4), (64, 8), (5, 10)):
        sizes = [s.stop - s.start for s in chunk_slices(n, chunk_size=size)]
        assert sum(sizes) == n and max(sizes) <= size and len(sizes) == -(-n // size)
    with pytest.raises(ValueError, match="exactly one"):
        chunk_slices(5)
    with pytest.raises(ValueError, match="chunk_size"):
        chunk_slices(5, chunk_size=0)


def test_bad_configuration_is_named() -> None:
    with pytest.raises(ValueError, match="unknown parallel backend 'spark'"):
        ParallelConfig(backend="spark")
    with pytest.raises(ValueError, match="n_workers must be at least 1"):
        ParallelConfig(n_workers=0)
    with pytest.raises(ValueError, match="scheduler address"):
        ParallelConfig(backend="local", scheduler="tcp://x:1")
    with pytest.raises(ValueError, match="either an executor"):
        with Executor(n_workers=1) as ex:
            map_chunks(_square, [[1]], n_workers=2, executor=ex)


def test_empty_chunk_list_gives_empty_result() -> None:
    assert map_chunks(_square, [], n_workers=2) == []


def test_task_errors_propagate_from_local_processes() -> None:
    with pytest.raises(ArithmeticError, match="chunk holding 4"):
        map_chunks(functools.partial(_fail_on, bad=4), [[1, 2], [3, 4]], n_workers=2)


@pytest.mark.skipif(importlib.util.find_spec("ray") is not None, reason="ray is installed")
def test_ray_missing_gives_install_hint() -> None:
    with pytest.raises(BackendUnavailableError, match=r"pip install 'cfteach\[ray\]'"):
        map_chunks(_square, [[1]], backend="ray")


def test_public_names() -> None:
    assert set(parallel.BACKENDS) == {"local", "dask", "ray"}


@pytest.mark.slow
def test_dask_executor_joins_an_existing_cluster_and_leaves_it_running() -> None:
    import logging

    from distributed import Client, LocalCluster

    chunks = chunked(DATA, chunk_size=10)
    expected = map_chunks(_draw, chunks, n_workers=1, seed=9)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        got = map_chunks(_draw, chunks, backend="dask", scheduler=cluster.scheduler_address,
                         seed=9)
        for a, b in zip(expected, got, strict=True):
            np.testing.assert_array_equal(a, b)
        with Client(cluster) as client:  # still up: the executor only joined it
            assert client.submit(sum, [1, 2]).result() == 3
