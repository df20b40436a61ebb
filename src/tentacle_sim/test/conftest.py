"""Device emulators opened as a driver opens them: a raw pty by its stable path."""

import os
import tty

import pytest


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
