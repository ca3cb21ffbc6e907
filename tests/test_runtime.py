"""The compilation cache a program opts into (``dockjax.enable_compilation_cache``): where
it goes, that an application's own cache is respected, that it can be turned off, and that
a new process really writes it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import dockjax
from dockjax import runtime


class _Config:
    """A stand-in for ``jax.config`` (the test process's real cache stays untouched)."""

    def __init__(self, cache_dir=None):
        self.jax_compilation_cache_dir = cache_dir
        self.updates = {}

    def update(self, name, value):
        self.updates[name] = value
        setattr(self, name, value)


@pytest.fixture
def config(monkeypatch):
    cfg = _Config()
    monkeypatch.setattr(runtime, "jax", type("jax", (), {"config": cfg}))
    return cfg


def test_the_folder_is_the_environments_or_the_home_cache(config, monkeypatch, tmp_path):
    monkeypatch.setenv("DOCKJAX_CACHE", str(tmp_path / "env"))
    assert dockjax.enable_compilation_cache() == tmp_path / "env" and (tmp_path / "env").is_dir()
    assert config.updates == {"jax_compilation_cache_dir": str(tmp_path / "env"),
                              "jax_persistent_cache_min_compile_time_secs": 0.0}
    monkeypatch.delenv("DOCKJAX_CACHE")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    config.jax_compilation_cache_dir = None
    assert dockjax.enable_compilation_cache() == tmp_path / "home" / ".cache" / "dockjax" / "jax"


def test_an_applications_own_cache_is_kept_unless_a_folder_is_given(config, monkeypatch, tmp_path):
    config.jax_compilation_cache_dir = str(tmp_path / "app")
    assert dockjax.enable_compilation_cache() == tmp_path / "app" and config.updates == {}
    monkeypatch.setenv("DOCKJAX_CACHE", "off")  # the application's choice wins over dockjax's variable
    assert dockjax.enable_compilation_cache() == tmp_path / "app" and config.updates == {}
    assert dockjax.enable_compilation_cache(tmp_path / "mine") == tmp_path / "mine"
    assert config.jax_compilation_cache_dir == str(tmp_path / "mine")


@pytest.mark.parametrize("value", ["off", "OFF", "0", "none", ""])
def test_the_environment_turns_it_off(config, monkeypatch, value):
    monkeypatch.setenv("DOCKJAX_CACHE", value)
    assert dockjax.enable_compilation_cache() is None and config.updates == {}


def test_a_folder_that_cannot_be_made_leaves_it_off(config, tmp_path):
    (tmp_path / "file").write_text("")
    assert dockjax.enable_compilation_cache(tmp_path / "file" / "cache") is None and config.updates == {}


def test_a_new_process_writes_its_programs_to_the_cache(tmp_path):
    """A program that opts in keeps even a quick compilation in the folder, for the next
    process to load."""
    code = ("import dockjax, jax, sys; folder = dockjax.enable_compilation_cache(); "
            "jax.jit(lambda x: x * 3.0 + 1.0)(2.0).block_until_ready(); print(folder)")
    env = {**os.environ, "DOCKJAX_CACHE": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert Path(r.stdout.strip()) == tmp_path / "cache"
    assert any(p.is_file() for p in (tmp_path / "cache").rglob("*")), "nothing was written to the cache"
