"""The simulated rig's devices: linked by DESIGN.md's names, one simulator a folder, faults."""

import os
import socket

import pytest
from tentacle_common.waiting import wait_for
from tentacle_sim.sim_devices import ask, CONTROL, ControlSocket, DeviceDirBusy, SimDevices


@pytest.fixture
def devices(tmp_path):
    """Return SimDevices with a backbone and its control socket, in tmp_path/dev."""
    made = SimDevices(tmp_path / 'dev', 'scpi', backbone=True)
    control = ControlSocket(made.dir / CONTROL, made.control)
    yield made
    control.close()
    made.stop()


def test_devices_are_linked_by_their_names_and_unlinked_at_stop(tmp_path):
    made = SimDevices(tmp_path / 'dev')
    names = {'coil_x', 'coil_y', 'coil_z', 'inserter'}
    assert names <= set(os.listdir(made.dir))
    assert all(os.path.realpath(made.dir / n).startswith('/dev/pts/') for n in names)
    made.stop()
    assert not names & set(os.listdir(tmp_path / 'dev'))
    SimDevices(tmp_path / 'dev').stop()   # the folder is free again


def test_a_second_simulator_on_the_same_folder_is_refused(devices):
    with pytest.raises(DeviceDirBusy, match='in use by another simulator'):
        SimDevices(devices.dir)
    assert 'backbone' in os.listdir(devices.dir)   # the first one's links untouched


def test_faults_and_state_over_the_control_socket(devices):
    state = ask(devices.dir, {'op': 'state'})
    assert set(state) == {'coil_x', 'coil_y', 'coil_z', 'inserter', 'backbone'}
    assert state['coil_y']['current_a'] == 0.0 and state['inserter']['position_m'] == 0.0
    assert ask(devices.dir, {'op': 'fault', 'port': 'coil_y', 'kind': 'disconnect',
                             'duration_s': 30.0}) == {'ok': True}
    assert wait_for(lambda: not devices.supplies['y'].connected, 5.0)   # its thread acts
    assert 'no port' in ask(devices.dir, {'op': 'fault', 'port': 'coil_q', 'kind': 'nak'})[
        'error']
    assert 'not a number' in ask(devices.dir, {'op': 'fault', 'port': 'inserter',
                                               'kind': 'stall', 'after_m': 'far'})['error']
    with socket.socket(socket.AF_UNIX) as raw:   # a malformed line is answered, not fatal
        raw.connect(str(devices.dir / CONTROL))
        raw.sendall(b'not json\n')
        assert b'error' in raw.recv(4096)
    assert ask(devices.dir, {'op': 'state'})['coil_x']['connected']


def test_the_world_reads_the_devices_truth(devices):
    assert devices.currents_a().tolist() == [0.0, 0.0, 0.0]
    assert devices.travel_m('inserter') == 0.0 and devices.travel_m('backbone') == 0.0
