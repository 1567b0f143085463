"""A bounded end for a node process: once the node has closed, the process ends within :data:`END_WITHIN_S`.

After a node's ``close()`` has saved its model and closed its devices, what
is left is tearing down the middleware (rclpy destroys the node, then the
context and its DDS participant).  That can block for good: Fast DDS pushes
a last discovery message into every peer's shared-memory port under a lock
that lives in ``/dev/shm``, and a process killed while it held that lock
(``SIGKILL``, a crash) leaves it locked.  The blocked call is native and
holds Python's GIL, so no Python thread or signal handler can run any more:
``ros2 launch`` then escalates to SIGTERM and SIGKILL, 15 s after Ctrl-C.

:func:`end_process_after` arms two POSIX timers (``timer_create`` with
``SIGEV_THREAD``, called through ctypes because no library wraps them): when
they expire, libc starts threads of its own that need no GIL; the first
writes a warning to stderr (``perror``), the second ends the process with
the status the node would have returned (``_exit``).  The process ends
normally if it gets there first, and the timers end with it.  Where the
timers cannot be armed (not glibc), :func:`faulthandler.dump_traceback_later`
ends the process instead, with its stack and status 1.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import faulthandler

__all__ = ["END_WITHIN_S", "end_process_after"]

#: A node process ends at most this long after its node closed [s]; ``ros2 launch`` sends SIGTERM 5 s after
#: Ctrl-C, and stopping spinning and ``close()`` come first.
END_WITHIN_S = 3.0
#: The warning is written this long before the process ends [s]: its thread has to start and write.
_WARN_BEFORE_S = 0.2

_CLOCK_MONOTONIC = 1
_SIGEV_THREAD = 2


class _Sigevent(ctypes.Structure):
    """glibc's ``struct sigevent`` (64 bytes) as ``SIGEV_THREAD`` uses it."""

    _fields_ = [("sigev_value", ctypes.c_void_p),  # union sigval: handed to the function as its one argument
                ("sigev_signo", ctypes.c_int),
                ("sigev_notify", ctypes.c_int),
                ("sigev_notify_function", ctypes.c_void_p),
                ("sigev_notify_attributes", ctypes.c_void_p),
                ("_pad", ctypes.c_byte * 32)]


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [("it_interval", _Timespec), ("it_value", _Timespec)]


#: What the armed timers read when they expire (the message buffer) and their ids: alive until the process ends.
_armed: list[object] = []


def _libc_with_timers() -> ctypes.CDLL:
    libc = ctypes.CDLL(None, use_errno=True)  # so that ctypes.get_errno() reads a failed call's errno
    if hasattr(libc, "timer_create"):
        return libc
    rt = ctypes.util.find_library("rt")  # glibc before 2.34 keeps the timers in librt
    if rt is None:
        raise OSError("no timer_create in this C library")
    librt = ctypes.CDLL(rt, use_errno=True)
    libc.timer_create, libc.timer_settime = librt.timer_create, librt.timer_settime
    return libc


def _arm(libc: ctypes.CDLL, after_s: float, function: str, argument: int | None) -> None:
    """Call libc's one-argument ``function(argument)`` in a new thread ``after_s`` from now."""
    event = _Sigevent()
    event.sigev_notify = _SIGEV_THREAD
    event.sigev_notify_function = ctypes.cast(getattr(libc, function), ctypes.c_void_p).value
    event.sigev_value = argument
    timer = ctypes.c_void_p()
    if libc.timer_create(_CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) != 0:
        raise OSError(ctypes.get_errno(), "timer_create failed")
    sec = int(after_s)
    when = _Itimerspec(_Timespec(0, 0), _Timespec(sec, max(1, int((after_s - sec) * 1e9))))
    if libc.timer_settime(timer, 0, ctypes.byref(when), None) != 0:
        raise OSError(ctypes.get_errno(), "timer_settime failed")
    _armed.append(timer)


def end_process_after(limit_s: float, status: int, who: str, saved: bool = True) -> bool:
    """End this process ``limit_s`` from now with exit ``status``, whatever its threads are doing.

    Parameters
    ----------
    limit_s
        Seconds from now; the process ends normally if it gets there first.
    status
        The exit status to end with (the one the node would have returned).
    who
        The node's logger name, for the warning.
    saved
        Whether the node's ``close()`` finished (the warning says so, or that it failed).

    Returns
    -------
    bool
        ``True`` if the timers are armed; ``False`` if only the fault handler's timer could be (the
        process then ends with its Python stack and status 1).
    """
    closing = "everything was saved" if saved else "closing had failed (logged above)"
    text = (f"[WARN] [{who}]: still not ended {limit_s:.1f} s after the node closed (tearing down the "
            f"middleware blocked, or slower than that); {closing}; ending with status {status}")
    message = ctypes.create_string_buffer(text.encode())
    try:
        libc = _libc_with_timers()
        _arm(libc, max(limit_s - _WARN_BEFORE_S, 0.0), "perror", ctypes.addressof(message))
        _arm(libc, limit_s, "_exit", status)
    except (OSError, AttributeError):
        faulthandler.dump_traceback_later(limit_s, exit=True)
        return False
    _armed.append(message)
    return True
