"""Importing jrigid points JAX's persistent compilation cache at a directory of its own
(``jrigid._cache``), unless the user chose otherwise.

The mechanism is checked where it acts: in fresh interpreters, a program compiled by one
process is written to the directory and loaded from it by the next (JAX's cache-hit
event), whether jrigid is imported before or after JAX; a cache directory the user set,
the opt-out, and a directory that cannot be written leave JAX's cache alone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from jrigid import _cache

# A small program, written to the cache whatever its compile time.
_SCRIPT = """
import json, sys
order = sys.argv[1]
if order == "jrigid_first":
    import jrigid
import jax
import jax.numpy as jnp
if order != "jrigid_first":
    import jrigid
hits = []
jax.monitoring.register_event_listener(
    lambda event, **kw: hits.append(event) if event.endswith("cache_hits") else None)
min_time = jax.config.jax_persistent_cache_min_compile_time_secs
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
jax.jit(lambda x: jnp.sin(x) * jnp.cos(x) + 1.5)(jnp.arange(7.0)).block_until_ready()
print(json.dumps({"dir": jax.config.jax_compilation_cache_dir, "hits": len(hits),
                  "max": jax.config.jax_compilation_cache_max_size, "min_time": min_time}))
"""


def _run(env_updates: dict[str, str | None], order: str = "jrigid_first") -> dict:
    env = dict(os.environ)
    for key in (_cache.ENV, "JAX_COMPILATION_CACHE_DIR",
                "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"):
        env.pop(key, None)
    for key, value in env_updates.items():
        if value is not None:
            env[key] = value
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(_SCRIPT), order], env=env,
                         capture_output=True, text=True, check=True, timeout=300)
    assert "Error writing" not in out.stderr, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("order", ["jrigid_first", "jax_first"])
def test_a_second_process_loads_what_the_first_compiled(tmp_path, order):
    cache = str(tmp_path / "cache")
    first = _run({_cache.ENV: cache}, order)
    assert first == {"dir": cache, "hits": 0, "max": _cache.MAX_BYTES,
                     "min_time": _cache.MIN_COMPILE_SECONDS}
    assert any(name.endswith("-cache") for name in os.listdir(cache)), os.listdir(cache)
    assert (os.stat(cache).st_mode & 0o077) == 0  # the owner's only
    second = _run({_cache.ENV: cache}, order)
    assert second["dir"] == cache and second["hits"] >= 1


def test_a_shortest_compile_time_the_user_chose_is_kept(tmp_path):
    run = _run({_cache.ENV: str(tmp_path / "cache"),
                "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "2.5"})
    assert run["min_time"] == 2.5 and run["dir"] == str(tmp_path / "cache")


def test_the_default_directory_is_below_the_users_cache(tmp_path):
    run = _run({"XDG_CACHE_HOME": str(tmp_path)})
    expected = os.path.join(str(tmp_path), _cache.DEFAULT_DIR)
    assert run["dir"] == expected and os.listdir(expected)


def test_a_directory_the_user_chose_for_jax_is_kept(tmp_path):
    theirs = str(tmp_path / "theirs")
    run = _run({"JAX_COMPILATION_CACHE_DIR": theirs, _cache.ENV: str(tmp_path / "ours")})
    assert run["dir"] == theirs and run["max"] == -1 and run["min_time"] == 1.0  # JAX's own
    assert not (tmp_path / "ours").exists()


@pytest.mark.parametrize("value", ["off", "0", ""])
def test_the_cache_can_be_turned_off(value):
    assert _run({_cache.ENV: value})["dir"] is None


def test_a_directory_that_cannot_be_made_turns_the_cache_off_silently(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert _run({_cache.ENV: str(blocker / "cache")})["dir"] is None


@pytest.mark.parametrize(
    "environ, expected",
    [
        ({"XDG_CACHE_HOME": "/c", "HOME": "/h"}, os.path.join("/c", _cache.DEFAULT_DIR)),
        ({"HOME": "/h"}, os.path.join("/h", ".cache", _cache.DEFAULT_DIR)),
        ({"HOME": "/h", "XDG_CACHE_HOME": ""}, os.path.join("/h", ".cache", _cache.DEFAULT_DIR)),
        ({_cache.ENV: "/x/y", "XDG_CACHE_HOME": "/c"}, "/x/y"),
        ({_cache.ENV: "~/z", "HOME": "/h"}, "/h/z"),
        ({_cache.ENV: " OFF ", "XDG_CACHE_HOME": "/c"}, None),
        ({_cache.ENV: "None"}, None),
        ({_cache.ENV: "false"}, None),
    ],
    ids=["xdg", "home", "empty_xdg", "chosen", "chosen_home", "off", "none", "false"],
)
def test_cache_dir(environ, expected, monkeypatch):
    if "HOME" in environ:
        monkeypatch.setenv("HOME", environ["HOME"])
    assert _cache.cache_dir(environ) == expected
