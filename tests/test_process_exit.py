"""
A driver's exit: once its safe stop is confirmed, no signal turns the exit into a kill.

CI once saw the campaign's 'SIGINT x2 + SIGTERM' end with exit code -15 after the node had
printed 'outputs zero and off': the SIGTERM reached the node while the interpreter was
finalising, when Python has put its handlers back to the default. Here a real run_node
process, and a real driver child process, is held inside finalisation (an object whose
destructor waits for the test) while the test sends the signal: a forced ordering, not a
race.
"""

import os
import signal
import subprocess
import sys
import textwrap
import threading

import pytest
from rig_support import ROOT  # noqa: F401 (a private ROS domain for the node below)

# Freed by the collection the interpreter runs once it has dropped its signal handlers (a
# cycle, with automatic collection off so nothing frees it sooner): says so on stdout with
# what getsignal then answers (None: no Python handler any more), then waits for a byte on
# the file descriptor argv[1].
HOLD = textwrap.dedent("""
    import gc
    import os
    import signal
    import sys


    class HoldFinalisation:
        def __del__(self, write=os.write, read=os.read, getsignal=signal.getsignal,
                    fd=int(sys.argv[1])):
            write(1, b'finalising, SIGTERM handler %r\\n' % getsignal(signal.SIGTERM))
            read(fd, 1)


    gc.disable()
    held = HoldFinalisation()
    held.cycle = held
    del held
""")

NODE = HOLD + textwrap.dedent("""
    from rclpy.node import Node
    from tentacle_common.driver_node import run_node


    def make_node():
        node = Node('exit_probe')
        node.create_timer(0.01, lambda: print('spinning', flush=True))
        return node


    run_node(sys.argv[2:], 'exit_probe', [], 'a node that only exits\\n', make_node,
             lambda node: 'stopped')
""")

SLOW = textwrap.dedent("""
    import sys
    import time

    from tentacle_common.driver_node import run_node


    def make_node():
        print('building', flush=True)
        time.sleep(60.0)   # a node still opening its devices


    run_node(sys.argv[2:], 'slow_probe', [], 'a node slow to build\\n', make_node,
             lambda node: 'stopped')
""")

CHILD = HOLD + textwrap.dedent("""
    from tentacle_common.child_process import child_main


    class Driver:
        def __init__(self, config, emit):
            pass

        def handle(self, request):
            return None

        def state(self):
            return {}

        def shutdown(self, reason):
            return {'safe': True}


    child_main(Driver, 'exit_probe', state_period_s=60.0)
""")


FINALISING = 'finalising, SIGTERM handler None'


def started(script, limit_s=60.0):
    """
    Start ``script``; return (process, the write end of its finalisation hold).

    The process is killed after limit_s whatever happens, so a read of its output that
    waits for a line never waits for ever (it ends at the output's end, and fails).
    """
    hold_read, hold_write = os.pipe()
    proc = subprocess.Popen([sys.executable, '-c', script, str(hold_read)], text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, pass_fds=[hold_read])
    os.close(hold_read)
    limit = threading.Timer(limit_s, proc.kill)
    limit.daemon = True
    limit.start()
    return proc, hold_write


def line_from(proc, wanted):
    """Read the process's stdout up to a line containing ``wanted``; fail with what came."""
    seen = []
    for line in proc.stdout:
        if wanted in line:
            return
        seen.append(line)
    pytest.fail(f'no {wanted!r} line; it printed {seen!r} and {proc.stderr.read()!r}')


def release_and_wait(proc, hold_write):
    """Let finalisation go on; return the exit code."""
    try:
        os.write(hold_write, b'\n')
    except BrokenPipeError:  # the signal killed it already
        pass
    return proc.wait(20)


@pytest.mark.parametrize('late', [signal.SIGTERM, signal.SIGINT])
def test_a_signal_while_the_node_finalises_leaves_a_clean_exit(late):
    proc, hold = started(NODE)
    try:
        line_from(proc, 'spinning')
        proc.send_signal(signal.SIGINT)
        line_from(proc, FINALISING)     # stopped, confirmed, and now inside finalisation
        proc.send_signal(late)          # a default disposition would end the process here
        assert release_and_wait(proc, hold) == 0, proc.stderr.read()
        assert 'exit_probe: stopped' in proc.stderr.read()
    finally:
        proc.kill()
        proc.wait()
        os.close(hold)


def test_a_sigterm_while_a_driver_child_finalises_leaves_a_clean_exit():
    proc, hold = started(CHILD)
    try:
        proc.stdin.write('{"op": "config", "config": {}}\n')
        proc.stdin.flush()
        line_from(proc, '"ev": "ready"')
        proc.send_signal(signal.SIGTERM)   # the node's way to stop it
        line_from(proc, '"ev": "stopped"')
        line_from(proc, FINALISING)
        proc.send_signal(signal.SIGTERM)
        assert release_and_wait(proc, hold) == 0, proc.stderr.read()
    finally:
        proc.kill()
        proc.wait()
        os.close(hold)


def test_a_signal_while_the_node_is_built_is_not_a_clean_exit():
    proc, hold = started(SLOW)
    try:
        line_from(proc, 'building')
        proc.send_signal(signal.SIGINT)
        assert proc.wait(20) == 130          # no node: nothing it could confirm safe
        err = proc.stderr.read()
        assert 'slow_probe: interrupted while starting: no safe stop confirmed' in err, err
        assert 'Traceback' not in err
    finally:
        proc.kill()
        proc.wait()
        os.close(hold)
