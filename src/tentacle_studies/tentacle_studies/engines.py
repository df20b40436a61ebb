"""
Where a study's chunks are computed: in this process, or on a Dask cluster (local or remote).

A chunk is some thousands of points solved in one compiled pass: tens of milliseconds to
seconds, well above Dask's task overhead (0.2-1 ms: ../shared/NOTES.md section 13), so one
task a chunk. This machine's cores are a LocalCluster of one single-threaded worker process
a core; a lab's cluster is the same code with its scheduler's address. Either way the
chunks, and so the results, are the same: each chunk's first point starts straight.
"""

import contextlib
import json
import os
import pathlib
import subprocess
import sys
import time

from tentacle_studies import equilibria

PACKAGES = pathlib.Path(__file__).resolve().parents[2]   # src/: what a worker imports


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


@contextlib.contextmanager
def cluster_processes(folder, workers):
    """
    Start a Dask scheduler and its worker processes here, as a lab starts them; yield its address.

    ``dask scheduler`` and ``dask worker --nworkers N --nthreads 1``, separate processes on
    this machine with this checkout's packages on their path, their output in
    folder/dask.log: a cluster for tests and benchmarks (a lab's runs elsewhere). Stopped,
    every process, on leaving.

    :raises RuntimeError: the scheduler or its workers not up within 60 s
    """
    dask = str(pathlib.Path(sys.executable).parent / 'dask')
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        str(p) for p in sorted(PACKAGES.iterdir()) if (p / 'package.xml').exists()))
    folder = pathlib.Path(folder)
    scheduler_file = folder / 'scheduler.json'
    with open(folder / 'dask.log', 'w') as logs, contextlib.ExitStack() as stack:
        def start(*argv):
            process = subprocess.Popen([dask, *argv, '--no-dashboard'], env=env, stdout=logs,
                                       stderr=logs)
            stack.callback(_stop, process)
            return process
        start('scheduler', '--host', '127.0.0.1', '--port', '0', '--scheduler-file',
              str(scheduler_file))
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        if not scheduler_file.exists():   # once more at the deadline
            raise RuntimeError(f'no Dask scheduler within 60 s: {folder / "dask.log"}')
        start('worker', '--scheduler-file', str(scheduler_file), '--nworkers', str(workers),
              '--nthreads', '1')
        from distributed import Client
        address = json.loads(scheduler_file.read_text())['address']
        with Client(address) as client:
            try:
                client.wait_for_workers(workers, timeout=60)
            except TimeoutError:
                raise RuntimeError(f'{workers} Dask workers not up within 60 s: '
                                   f'{folder / "dask.log"}') from None
        yield address


def _stop(process):
    """Stop a process: terminate, then kill after 30 s."""
    process.terminate()
    try:
        process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
