"""Mapping a worker function over jobs in one process or a ``multiprocessing.Pool``, with a progress bar.

Shared by the ``prepare`` commands (:mod:`mocapkit.datasets.ntu.prepare`,
:mod:`mocapkit.datasets.casia_b.prepare`), which consume results in job order, and by the
synthetic data sets (:mod:`mocapkit.datasets.synthetic`), whose workers write files and
report them in any order.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from multiprocessing import Pool


class parallel_map:
    """``with parallel_map(fn, jobs, workers) as results:`` iterates ``fn(job)`` in job order.

    One worker maps in this process; more use a ``multiprocessing.Pool`` with ``imap``
    (order kept, results streamed) and a chunk size of ``len(jobs) // (8 * workers)``, clipped
    to ``1..max_chunksize``, which keeps workers busy without holding many results in memory.
    Leaving the block terminates the pool.

    With ``desc``, a tqdm bar (``unit``; hidden unless ``progress``) ticks as each result is taken.
    """

    def __init__(
        self,
        fn: Callable,
        jobs: list,
        workers: int,
        max_chunksize: int = 16,
        desc: str | None = None,
        unit: str = "it",
        progress: bool = True,
    ):
        self.fn, self.jobs, self.workers, self.max_chunksize = fn, jobs, workers, max_chunksize
        self.desc, self.unit, self.progress = desc, unit, progress
        self.pool = None
        self.bar = None

    def __enter__(self) -> Iterator:
        if self.workers == 1:
            results = map(self.fn, self.jobs)
        else:
            self.pool = Pool(self.workers)
            chunksize = max(1, min(self.max_chunksize, len(self.jobs) // (self.workers * 8)))
            results = self.pool.imap(self.fn, self.jobs, chunksize=chunksize)
        if self.desc is None:
            return results
        from tqdm import tqdm

        self.bar = tqdm(total=len(self.jobs), desc=self.desc, unit=self.unit, disable=not self.progress)
        return self._ticking(results)

    def _ticking(self, results: Iterator) -> Iterator:
        for result in results:
            self.bar.update(1)
            yield result

    def __exit__(self, *exc_info):
        if self.bar is not None:
            self.bar.close()
        if self.pool is not None:
            self.pool.terminate()
            self.pool.join()
        return False


def write_all(
    fn: Callable[..., list],
    jobs: list,
    workers: int,
    total: int,
    desc: str,
    unit: str,
    progress: bool = True,
    chunksize: int = 1,
) -> None:
    """Run ``fn(job)`` for every job, in this process (``workers == 1``) or in a pool in any order.

    ``fn`` writes files and returns the list of what it wrote; the tqdm bar (``total`` items of
    ``unit``, hidden unless ``progress``) advances by the length of each list.
    """
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit=unit, disable=not progress)
    try:
        if workers == 1:
            for job in jobs:
                bar.update(len(fn(job)))
        else:
            with Pool(workers) as pool:
                for written in pool.imap_unordered(fn, jobs, chunksize=chunksize):
                    bar.update(len(written))
    finally:
        bar.close()
