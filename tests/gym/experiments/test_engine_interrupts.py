"""An interrupt that lands in a finaliser, and SIGTERM, stop a protocol's run like Ctrl-C."""

from __future__ import annotations

import signal
import sys

import pytest

from lfmdr_gym.cli import _terminate
from lfmdr_gym.experiments.engine import _remembered_interrupt


class _Finaliser:
    """An object whose finaliser is where the signal lands (as in numpy's NpzFile.__del__)."""

    def __init__(self, action):
        self.action = action

    def __del__(self):
        self.action()


def _recording_hook(monkeypatch) -> list:
    seen: list = []
    monkeypatch.setattr(sys, "unraisablehook", lambda unraisable: seen.append(unraisable))
    return seen


def test_an_interrupt_swallowed_by_a_finaliser_is_remembered_and_not_reported(monkeypatch):
    seen = _recording_hook(monkeypatch)
    hook, handler = sys.unraisablehook, signal.getsignal(signal.SIGINT)
    with _remembered_interrupt() as interrupt:
        _Finaliser(lambda: signal.getsignal(signal.SIGINT)(signal.SIGINT, None))  # Ctrl-C here
        assert interrupt.event.is_set()
        with pytest.raises(KeyboardInterrupt):
            interrupt.raise_if_set()
        # another error of a finaliser is still reported
        _Finaliser(lambda: 1 / 0)
    assert [type(u.exc_value) for u in seen] == [ZeroDivisionError]
    assert sys.unraisablehook is hook and signal.getsignal(signal.SIGINT) is handler  # restored
    _Finaliser(lambda: signal.default_int_handler(signal.SIGINT, None))  # outside a run
    assert [type(u.exc_value) for u in seen] == [ZeroDivisionError, KeyboardInterrupt]


def test_sigterm_goes_through_whatever_handles_sigint():
    with _remembered_interrupt() as interrupt:
        with pytest.raises(KeyboardInterrupt):
            _terminate(signal.SIGTERM, None)
        assert interrupt.event.is_set()  # so it stops the run even if it lands in a finaliser
    with pytest.raises(KeyboardInterrupt):  # outside a run: Python's own SIGINT handler
        _terminate(signal.SIGTERM, None)
