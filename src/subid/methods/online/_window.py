"""The most recent samples of a stream in a buffer of fixed size.

:class:`subid.RecursiveSubspace` keeps no record, only its running factor; its current
model's innovation covariance is the covariance of that model's one-step prediction
errors on the last samples of the stream
(:func:`subid.methods.dt.noise_model.prediction_error_covariance`), which this window
holds: memory bounded by its size, whatever the length of the stream.
"""

from __future__ import annotations

import math

import numpy as np

from subid.data import IOData

#: Samples the window holds at most (forgetting 1).
NOISE_WINDOW = 10_000
#: With forgetting ``λ < 1`` the window spans this many memories ``1 / (1 - λ)`` (the
#: current model describes the recent data), within [:data:`MIN_WINDOW`, NOISE_WINDOW].
WINDOW_MEMORIES = 3
#: The smallest window.
MIN_WINDOW = 200


def window_size(forgetting: float) -> int:
    """The number of samples the window of an identifier with this forgetting holds."""
    if forgetting >= 1.0:
        return NOISE_WINDOW
    memory = 1.0 / (1.0 - forgetting)
    return int(min(NOISE_WINDOW, max(MIN_WINDOW, math.ceil(WINDOW_MEMORIES * memory))))


class SampleWindow:
    """A ring buffer of the last ``size`` samples of ``(u, y)``."""

    def __init__(self, n_inputs: int, n_outputs: int, size: int):
        self.size = int(size)
        self._u = np.zeros((self.size, n_inputs))
        self._y = np.zeros((self.size, n_outputs))
        self.count = 0                # samples held (at most size)
        self._head = 0                # where the next sample goes

    def add(self, u: np.ndarray, y: np.ndarray) -> None:
        """Append a chunk (time on axis 0); the oldest samples leave."""
        k = u.shape[0]
        if k == 1:                    # a stream's usual call: two row copies
            h = self._head
            self._u[h], self._y[h] = u[0], y[0]
            self._head = h + 1 if h + 1 < self.size else 0
            if self.count < self.size:
                self.count += 1
            return
        if k >= self.size:
            self._u[:], self._y[:] = u[-self.size:], y[-self.size:]
            self._head, self.count = 0, self.size
            return
        first = min(k, self.size - self._head)
        self._u[self._head:self._head + first] = u[:first]
        self._y[self._head:self._head + first] = y[:first]
        self._u[:k - first] = u[first:]
        self._y[:k - first] = y[first:]
        self._head = (self._head + k) % self.size
        self.count = min(self.size, self.count + k)

    def ordered(self) -> tuple[np.ndarray, np.ndarray]:
        """The samples held, oldest first (copies)."""
        if self.count < self.size:
            return self._u[:self.count].copy(), self._y[:self.count].copy()
        order = np.r_[self._head:self.size, 0:self._head]
        return self._u[order], self._y[order]

    def record(self, dt: float) -> IOData | None:
        """The samples held as a record, or None when empty."""
        if not self.count:
            return None
        u, y = self.ordered()
        return IOData(u, y, dt=dt, copy=False)

    def restore(self, u: np.ndarray, y: np.ndarray) -> None:
        """Hold ``(u, y)`` (oldest first), as :meth:`ordered` gave them."""
        self._head, self.count = 0, 0
        self.add(np.asarray(u, dtype=float), np.asarray(y, dtype=float))
