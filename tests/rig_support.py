"""
What the cross-process tests share: a private ROS domain, the root, waiting, spinning.

The spin thread (Spinner) ends before its executor is shut down.

Every run claims a private ROS_DOMAIN_ID (a lock file per domain, so parallel runs on one
machine never share one) with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, before rclpy is
imported. Import it before rclpy (tests/conftest.py does).
"""

import fcntl
import os
import pathlib
import threading

from tentacle_common.waiting import wait_for  # noqa: F401 (the tests take it from here)


ROOT = pathlib.Path(__file__).resolve().parent.parent
DOMAIN_RANGE = range(100, 200)


def _claim_domain():
    for domain in [100 + (os.getpid() + k) % 100 for k in range(len(DOMAIN_RANGE))]:
        handle = open(f'/tmp/tentacle_rig_ros_domain_{domain}.lock', 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain, handle
        except OSError:
            handle.close()
    raise RuntimeError('no free ROS_DOMAIN_ID in 100..199')


DOMAIN_ID, _DOMAIN_LOCK = _claim_domain()
os.environ['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['PYTHONUNBUFFERED'] = '1'


class Spinner:
    """
    Spin an rclpy executor on a thread of its own until ``stop()``.

    The thread ends before the executor is shut down: ``Executor.shutdown`` destroys a guard
    condition that a spin still running may trigger (InvalidHandle in the spin thread).
    """

    def __init__(self, executor, period_s=0.05):
        """Start spinning ``executor``, waking every ``period_s`` to look for stop()."""
        self.executor, self.period_s = executor, period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=self.period_s)

    def stop(self):
        """End the spin thread, then shut the executor down."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.executor.shutdown()
