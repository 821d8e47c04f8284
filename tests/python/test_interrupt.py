"""Ctrl-C during an extraction stops it and raises KeyboardInterrupt, never a crash."""

import os
import signal
import threading

import pytest

import isobar


def test_ctrl_c_raises_keyboard_interrupt(dam_break_path, python_sigint):
    particles = isobar.Particles.read(dam_break_path)
    isobar.extract(particles, 0.6, h=0.05, grid_factor=0.2)  # warm up
    for _ in range(5):
        timer = threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT))
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            # Long enough that the signal arrives while the core runs.
            isobar.extract(particles, 0.6, h=0.05, grid_factor=0.1)
        timer.join()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
