"""Device emulators opened as a driver opens them (a raw pty by its stable path); scenes."""

import os
import pathlib
import tty

import numpy as np
import pytest
from tentacle_planner.scene import load_scene
import yaml


@pytest.fixture
def on_pty(tmp_path):
    """Return make(device class, *args, **kwargs) -> (started device, raw fd to it)."""
    made = []

    def make(kind, *args, **kwargs):
        dev = kind(*args, link_path=str(tmp_path / 'dev'), **kwargs).start()
        fd = os.open(dev.port, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        made.append((dev, fd))
        return dev, fd
    yield make
    for dev, fd in made:
        os.close(fd)
        dev.stop()


class Cantilever:
    """The validation cantilever (config/tentacles/cantilever.yaml) and its closed forms."""

    FILE = pathlib.Path(__file__).resolve().parents[3] / 'config' / 'tentacles' / (
        'cantilever.yaml')
    LENGTH_M = 0.020
    RADIUS_M = 0.001
    EI_N_M2 = 1.0e5 * np.pi * 0.002 ** 4 / 64            # a 2 mm rod of 100 kPa
    MA_A_M = 0.107 / (4e-7 * np.pi) * np.pi * 0.001 ** 2   # Br / mu0 times the section area

    def __init__(self, folder):
        self.folder = folder

    def scene(self, sublinks=32, **extra):
        """Write a scene of it (planar, straight path along x); return the Scene."""
        document = {
            'name': 'sim_cantilever', 'tentacle': str(self.FILE),
            'path': {'points_m': [[float(x), 0.0, 0.0]
                                  for x in np.linspace(0.0, self.LENGTH_M, 21)]},
            'insertion_steps_m': [self.LENGTH_M],
            'model': {'dof': 1, 'sublinks': sublinks}, **extra}
        path = pathlib.Path(self.folder) / f'sim_cantilever_{len(os.listdir(self.folder))}.yaml'
        path.write_text(yaml.safe_dump(document))
        return load_scene(path)


@pytest.fixture
def cantilever(tmp_path):
    """Return a Cantilever writing its scenes into tmp_path."""
    return Cantilever(tmp_path)
