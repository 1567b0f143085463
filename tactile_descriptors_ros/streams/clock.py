"""Device time -> host time: a sample's stamp is when it was acquired, on the host clock, never in the future.

A sensor counts time on its own clock: the BioTac bridge's microsecond
clock, the SPI frame counter times the frame period, a skin cell's sequence
numbers times its nominal sample period.  The host sees each sample only
after a transport delay ``d >= 0`` (the wire, the adapter's buffer, the
reader's wake-up, a driver that was starved of CPU), so every read gives one
inequality about the offset ``c`` between the two clocks::

    host_read - device_newest = c + d  >=  c

:class:`DeviceClock` keeps, per device clock (a *key*), the lower envelope of
these observations: the minimum of ``host_read - device_newest`` over every
read so far, allowed to rise by at most ``drift_ppm`` of the device time
elapsed between reads (a device oscillator runs slightly fast or slow; a
falling offset is followed at once by the minimum itself).  The estimate
converges to ``c + d_min``, the offset plus the least transport delay ever
seen, which a reader that waits for frames reaches within a few reads; the
error of a stamp is ``d_min`` plus the drift allowed since the last read
that saw the least delay.

Stamps are ``device_time + estimate``.  A read updates the estimate with its
newest sample *before* its samples are stamped, and the estimate never
exceeds that observation, so no sample is stamped after the host time of
the read that returned it: a stamp is never in the future.  A backlog (the
oldest frames of a buffer read long after they were taken, a driver starved
for seconds) only gives larger observations, which the minimum ignores.
This is the one-way form of the minimum-delay clock estimation of NTP's
clock filter and of TICSync (Harrison and Newman, ICRA 2011).

Two events re-anchor a key (``resyncs``): its device time steps back by
more than ``jump_ns`` (a device that restarted its clock), or every
observation for ``confirm_ns`` of host time lies more than ``jump_ns`` above
the estimate (a device clock slower than ``drift_ppm`` allows, or one that
stopped and resumed: the SPI frame counter does not count while nobody
reads).  :meth:`DeviceClock.reset` forgets keys (a replugged device, a new
configuration).

Pure numpy, no ROS: the BioTac and the skin streams share this one
implementation (:mod:`.biotac`, :mod:`.skin`).
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError

__all__ = ["DeviceClock", "DRIFT_PPM", "CONFIRM_S"]

#: Largest rate difference between a device clock and the host clock the estimate follows upwards [ppm]
#: (quartz oscillators: within 100 ppm).  It is also the error a stamp gains per second without a read
#: that saw the least delay: 0.5 ms per second.
DRIFT_PPM = 500.0
#: Observations must exceed the estimate by ``jump_ns`` for this long [s] before a key is re-anchored.
CONFIRM_S = 5.0


class DeviceClock:
    """Offsets from device clocks to the host clock, one per key (see the module docstring).

    Parameters
    ----------
    n_keys : int
        Number of device clocks (keys ``0 .. n_keys - 1``).
    drift_ppm : float
        How fast the estimate may rise per device second [ppm].
    jump_ns : int
        A device time step back, or a lasting excess of the observations over
        the estimate, beyond this re-anchors the key [ns]; 0 = never.
    confirm_ns : int
        How long [ns of host time] every observation must exceed the estimate
        by ``jump_ns`` before the key is re-anchored.

    Attributes
    ----------
    resyncs : int
        Keys re-anchored after a jump (not counting first anchors and resets).
    observations : int
        Observations taken (one per key and read).
    """

    def __init__(self, n_keys: int, drift_ppm: float = DRIFT_PPM, jump_ns: int = 1_000_000_000,
                 confirm_ns: int = int(CONFIRM_S * 1e9)) -> None:
        if not np.isfinite(drift_ppm) or drift_ppm < 0:
            raise ConfigError(f"must be a finite, non-negative rate in ppm, got {drift_ppm!r}", key="drift_ppm")
        if jump_ns < 0 or confirm_ns < 0:
            raise ConfigError("jump and confirm times must not be negative", key="resync_s")
        n = int(n_keys)
        self.drift = float(drift_ppm) * 1e-6
        self.jump_ns = int(jump_ns)
        self.confirm_ns = int(confirm_ns)
        self.offset_ns = np.zeros(n, np.int64)
        self.anchored = np.zeros(n, bool)
        self._last_dev = np.zeros(n, np.int64)
        self._high_since = np.full(n, -1, np.int64)  # host time of the first observation of a lasting excess
        self._high_min = np.zeros(n, np.int64)  # least observation during that excess
        self.last_excess_ns = np.zeros(n, np.int64)  # observation minus estimate of each key's last read
        self.resyncs = 0
        self.observations = 0

    def __len__(self) -> int:
        return int(self.offset_ns.size)

    def reset(self, keys: np.ndarray | None = None) -> None:
        """Forget ``keys`` (all when None): their next observation anchors them again."""
        sel = slice(None) if keys is None else np.asarray(keys, np.int64)
        self.anchored[sel] = False
        self._high_since[sel] = -1

    def observe(self, keys: np.ndarray, device_ns: np.ndarray, host_ns: int | np.ndarray) -> None:
        """One read's newest device time per key and the host time the read returned.

        Parameters
        ----------
        keys : array of int
            Distinct keys.
        device_ns : array of int64
            The newest sample's device time of each key in this read [ns].
        host_ns : int or array of int64
            Host time at which the read returned [ns] (after every one of its
            samples had arrived).
        """
        k = np.asarray(keys, np.int64)
        if not k.size:
            return
        dev = np.asarray(device_ns, np.int64)
        obs = np.asarray(host_ns, np.int64) - dev
        if obs.ndim == 0:
            obs = np.full(k.size, int(obs), np.int64)
        host = np.broadcast_to(np.asarray(host_ns, np.int64), k.shape)
        self.observations += int(k.size)
        new = ~self.anchored[k]
        off = self.offset_ns[k]
        last = self._last_dev[k]
        # the estimate may rise by drift * device time elapsed; the observation caps it (never in the future)
        allowed = off + (np.maximum(dev - last, 0) * self.drift).astype(np.int64)
        est = np.minimum(obs, allowed)
        back = np.zeros(k.size, bool)
        if self.jump_ns:
            back = ~new & (dev < last - self.jump_ns)  # the device clock restarted
            excess = obs - est
            high = ~new & ~back & (excess > self.jump_ns)
            since = self._high_since[k]
            start = high & (since < 0)
            since = np.where(start, host, np.where(high, since, -1))
            low = np.where(start, obs, np.minimum(self._high_min[k], obs))
            lasting = high & (host - since >= self.confirm_ns)
            est = np.where(back, obs, np.where(lasting, low, est))
            self.resyncs += int(back.sum() + lasting.sum())
            since = np.where(back | lasting, -1, since)
            self._high_since[k] = since
            self._high_min[k] = low
        est = np.where(new, obs, est)
        self._high_since[k[new]] = -1
        self.offset_ns[k] = est
        self._last_dev[k] = np.where(new | back, dev, np.maximum(dev, last))
        self.last_excess_ns[k] = obs - est
        self.anchored[k] = True

    def state(self) -> tuple[np.ndarray, ...]:
        """The per-key arrays :meth:`observe` updates, for a compiled pass that observes in place
        (``numba_kernel.skin_stamp_add``): offset, anchored, last device time, start and least observation of a
        lasting excess, last excess."""
        return (self.offset_ns, self.anchored, self._last_dev, self._high_since, self._high_min,
                self.last_excess_ns)

    def to_host(self, keys: np.ndarray | int, device_ns: np.ndarray | int) -> np.ndarray:
        """Host times [ns] of device times of (anchored) keys: ``device_ns + offset``."""
        return np.asarray(device_ns, np.int64) + self.offset_ns[keys]
