"""A least-recently-used memo of validated objects by a text key (the JSON text they were read from).

Validated designs and cases are frozen, so one instance can serve every caller that gives the same JSON; the
memo is shared by threads (a threaded Dask worker, a thread pool), so its lookups and insertions hold a lock.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any


class LRUMemo:
    """At most ``size`` objects by key, the least recently used dropped first."""

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"size {size!r} must be an integer >= 1")
        self.size = int(size)
        self._items: OrderedDict[str, Any] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: str) -> Any | None:
        """The object kept under ``key`` (now the most recently used), or None."""
        with self._lock:
            got = self._items.get(key)
            if got is not None:
                self._items.move_to_end(key)
            return got

    def put(self, key: str, value: Any) -> None:
        """Keep ``value`` under ``key``, dropping the least recently used beyond ``size``."""
        with self._lock:
            self._items[key] = value
            self._items.move_to_end(key)
            while len(self._items) > self.size:
                self._items.popitem(last=False)

    def __len__(self) -> int:
        return len(self._items)

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
