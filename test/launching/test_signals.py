"""The stop flag that Ctrl-C and SIGTERM raise in the launcher, the recorder and the player."""

from __future__ import annotations

import os
import signal
import threading

import pytest

from tactile_descriptors_ros.launching.signals import SignalStop, stop_on_signals


def _call_holding(lock_owner, handler) -> threading.Thread:
    """Run ``handler(SIGINT)`` in a thread that holds ``lock_owner``'s lock, as the main thread does inside ``wait``."""
    def run() -> None:
        with lock_owner:
            handler(signal.SIGINT, None)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_a_handler_that_sets_an_event_hangs_when_its_thread_holds_the_events_lock():
    """The hazard the flag exists for: ``Event.set`` in a handler waits on a lock its own thread holds."""
    event = threading.Event()
    thread = _call_holding(event._cond, lambda signum, frame: event.set())
    thread.join(1.0)
    assert thread.is_alive(), "Event.set() returned although the same thread held the event's lock"


def test_a_signal_while_the_stop_flags_lock_is_held_requests_a_stop_at_once():
    with stop_on_signals() as stop:
        handler = signal.getsignal(signal.SIGINT)
    thread = _call_holding(stop._event._cond, handler)
    thread.join(5.0)
    assert not thread.is_alive(), "the signal handler blocked on the stop flag's lock"
    assert stop.is_set()


def test_sigint_and_sigterm_request_a_stop_and_a_second_signal_raises():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for sig in (signal.SIGINT, signal.SIGTERM):
        with stop_on_signals() as stop:
            assert not stop.is_set()
            os.kill(os.getpid(), sig)  # the handler runs in this thread before the next bytecodes
            assert stop.wait(5.0)
            with pytest.raises(KeyboardInterrupt):
                os.kill(os.getpid(), sig)
                stop.wait(5.0)  # not reached: the second signal raises
    assert {s: signal.getsignal(s) for s in before} == before


def test_the_launchers_flag_takes_every_signal_without_raising():
    with stop_on_signals(second_raises=False) as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        os.kill(os.getpid(), signal.SIGINT)
        assert stop.wait(5.0)


def test_wait_wakes_on_a_request_from_another_thread_and_times_out_without_one():
    stop = SignalStop(poll_s=0.05)
    assert stop.wait(0.1) is False
    woke = threading.Event()

    def waiter() -> None:
        if stop.wait():
            woke.set()

    thread = threading.Thread(target=waiter, daemon=True)
    thread.start()
    stop.request()
    assert woke.wait(5.0), "wait() did not see a request made without the lock"
    thread.join(5.0)
    set_stop = SignalStop(poll_s=60.0)  # set() wakes a waiter at once, not after a poll slice
    thread = threading.Thread(target=set_stop.wait, daemon=True)
    thread.start()
    set_stop.set()
    thread.join(5.0)
    assert not thread.is_alive()
