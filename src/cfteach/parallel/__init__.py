"""One executor interface over coarse, seeded chunks of work.

The work in cfteach multiplies (instances x human models x demonstrations x learners), so
the expensive stages are cut into a few coarse chunks and mapped with `map_chunks`. Each
chunk gets its own `numpy.random.SeedSequence` child, chosen by the chunk's *index*, and
results come back in chunk order: a run gives the same answer on 1 process, on all local
cores, on a Dask cluster or on Ray. See docs/parallel.md.
"""

from cfteach.parallel.executor import (
    BACKENDS,
    BackendUnavailableError,
    Executor,
    ParallelConfig,
    chunk_slices,
    chunked,
    map_chunks,
    spawn_seeds,
)

__all__ = [
    "BACKENDS",
    "BackendUnavailableError",
    "Executor",
    "ParallelConfig",
    "chunk_slices",
    "chunked",
    "map_chunks",
    "spawn_seeds",
]
