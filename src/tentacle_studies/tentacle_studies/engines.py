"""
Where a study's chunks are computed: in this process, or on a Dask cluster (local or remote).

A chunk is some thousands of points solved in one compiled pass: tens of milliseconds to
seconds, well above Dask's task overhead (0.2-1 ms: ../shared/NOTES.md section 13), so one
task a chunk. This machine's cores are a LocalCluster of one single-threaded worker process
a core; a lab's cluster is the same code with its scheduler's address. Either way the
chunks, and so the results, are the same: each chunk's first point starts straight.
"""

import contextlib
import os

from tentacle_studies import equilibria


def solve_points(study, start, stop):
    """Return the table columns of a study's points start..stop: equilibria or plans."""
    if study.compute == 'plan':
        from tentacle_studies import plans   # the planner: plan studies only
        return plans.plan_points(study, start, stop)
    return equilibria.solve_points(study, start, stop)


def local_cores():
    """Return the cores this process may run on."""
    return len(os.sched_getaffinity(0))


@contextlib.contextmanager
def in_process():
    """Yield compute(study, bounds) -> iterator of (index, columns) as chunks complete."""
    def compute(study, bounds):
        for index, (start, stop) in bounds.items():
            yield index, solve_points(study, start, stop)
    yield compute


@contextlib.contextmanager
def dask(address=None, workers=None):
    """
    Yield compute() as in_process, on a Dask cluster.

    :param address: a scheduler's address (tcp://host:port); None: a LocalCluster of
        ``workers`` single-threaded processes (default: local_cores())
    """
    from distributed import as_completed, Client, LocalCluster
    with contextlib.ExitStack() as stack:
        if address is None:
            # On this machine only, and its HTTP server on a free port: not the well-known
            # 8787, which another cluster (a lab's dashboard) may hold.
            cluster = stack.enter_context(LocalCluster(
                n_workers=workers or local_cores(), threads_per_worker=1, processes=True,
                host='127.0.0.1', dashboard_address=None,
                scheduler_kwargs={'dashboard': False, 'dashboard_address': '127.0.0.1:0'}))
            address = cluster.scheduler_address
        client = stack.enter_context(Client(address))

        def compute(study, bounds):
            shared = client.scatter(study, broadcast=True)
            futures = {client.submit(solve_points, shared, start, stop, pure=False): index
                       for index, (start, stop) in bounds.items()}
            try:
                for future in as_completed(futures):
                    yield futures[future], future.result()
            finally:
                client.cancel(list(futures))   # Ctrl-C: nothing left running on the cluster
        yield compute
