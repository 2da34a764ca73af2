"""Ctrl-C held back around work that must not stop half-way (core.cancel.interrupts_deferred)."""

from __future__ import annotations

import signal
import threading

import pytest

from workbench.core.cancel import interrupts_deferred


@pytest.fixture
def python_sigint():
    """SIGINT handled by Python's own handler during the test (as in the CLI)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_ctrl_c_is_delivered_when_the_block_ends(python_sigint) -> None:
    finished = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            signal.raise_signal(signal.SIGINT)
            total = sum(range(10_000))  # Python code runs on: the signal is held
            finished.append(total)
    assert finished == [sum(range(10_000))]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_nested_blocks_deliver_once_at_the_outer_end(python_sigint) -> None:
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            with interrupts_deferred():
                signal.raise_signal(signal.SIGINT)
                steps.append("inner")
            steps.append("outer")
    assert steps == ["inner", "outer"]


def test_no_interrupt_no_change_and_other_threads_untouched(python_sigint) -> None:
    with interrupts_deferred():
        pass
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    seen = []

    def worker() -> None:
        with interrupts_deferred():  # off the main thread: nothing to hold back
            seen.append(signal.getsignal(signal.SIGINT))

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen == [signal.default_int_handler]
