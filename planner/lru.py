"""The one bounded cache of the planner: what a process builds once and reuses (IPOPT solvers, continuations).

Entries are kept most recently used last; the least recently used goes first
when the cache is full.  Every operation holds the cache's lock, so threads
(the certification's helper threads) share one cache safely.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Callable, Hashable

from crosscert.robots.errors import InputError

__all__ = ["LruCache"]


class LruCache:
    """At most ``size`` values by hashable key, least recently used evicted first.

    Parameters
    ----------
    size : int
        Entries kept (>= 1).
    """

    def __init__(self, size: int):
        if int(size) != size or size < 1:
            raise InputError(f"an LruCache keeps at least one entry, got size={size!r}")
        self.size = int(size)
        self._items: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def get_or_build(self, key: Hashable, build: Callable[[], object]):
        """The value of ``key``, built by ``build()`` on a miss.  Room is made before building, so the cache
        never holds more than ``size`` values at once (a solver's workspace is large)."""
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
            while len(self._items) >= self.size:
                self._items.popitem(last=False)
            value = self._items[key] = build()
            return value

    def pop(self, key: Hashable, default=None):
        """Take ``key``'s value out of the cache (``default`` if absent)."""
        with self._lock:
            return self._items.pop(key, default)

    def put(self, key: Hashable, value) -> None:
        """Keep ``value`` as the most recently used, evicting the least recently used beyond ``size``."""
        with self._lock:
            self._items[key] = value
            self._items.move_to_end(key)
            while len(self._items) > self.size:
                self._items.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._items.clear()

    def __len__(self) -> int:
        return len(self._items)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._items
