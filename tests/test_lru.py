"""The planner's one bounded cache (planner.lru): least recently used out first, room made before a build."""

from __future__ import annotations

import pytest

from crosscert.planner.lru import LruCache
from crosscert.robots.errors import InputError


def test_the_least_recently_used_goes_first():
    cache = LruCache(2)
    assert cache.get_or_build("a", lambda: 1) == 1
    assert cache.get_or_build("b", lambda: 2) == 2
    assert cache.get_or_build("a", lambda: 99) == 1  # a hit: not rebuilt, now the most recent
    cache.get_or_build("c", lambda: 3)  # evicts b, the least recently used
    assert "a" in cache and "c" in cache and "b" not in cache and len(cache) == 2


def test_room_is_made_before_a_build():
    """A build never sees the cache over its size (the peak memory of solvers is the cache's size)."""
    cache = LruCache(2)
    cache.get_or_build("a", lambda: 1)
    cache.get_or_build("b", lambda: 2)
    seen = []
    cache.get_or_build("c", lambda: seen.append(len(cache)) or 3)
    assert seen == [1]


def test_put_and_pop_keep_the_order_and_the_size():
    cache = LruCache(2)
    cache.put("a", 1)
    cache.put("b", 2)
    assert cache.pop("a") == 1 and cache.pop("a", "none") == "none"
    cache.put("a", 10)  # back in, the most recent
    cache.put("c", 3)  # evicts b
    assert "b" not in cache and cache.pop("a") == 10 and len(cache) == 1
    cache.clear()
    assert len(cache) == 0 and not cache


@pytest.mark.parametrize("size", [0, -1, 1.5])
def test_a_cache_keeps_at_least_one_entry(size):
    with pytest.raises(InputError, match="at least one"):
        LruCache(size)
