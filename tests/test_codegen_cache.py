"""The compiled-library cache stays under its cap (least recently used first, recent ones spared) and
`thermo-ddp cache` reports and clears only the cache folder's libraries."""
import os
import time

import casadi as ca
import pytest

from thermo_ddp import codegen
from thermo_ddp.cli import main


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    folder.mkdir()
    monkeypatch.setenv("THERMO_DDP_CACHE", str(folder))
    monkeypatch.delenv("THERMO_DDP_CACHE_MAX_MB", raising=False)
    return folder


def _library(folder, name, size, used_s_ago):
    """A fake cached library of ``size`` bytes, last used ``used_s_ago`` seconds ago."""
    path = folder / f"{name}_{'0' * 19}{len(name) % 10}.so"
    path.write_bytes(b"x" * size)
    then = time.time_ns() - int(used_s_ago * 1e9)
    os.utime(path, ns=(then, then))
    return path


def test_cap_evicts_least_recently_used_first(cache):
    old = _library(cache, "old", 1000, used_s_ago=3600)
    middle = _library(cache, "middle", 1000, used_s_ago=1800)
    new = _library(cache, "new", 1000, used_s_ago=600)
    assert codegen.trim_cache(max_bytes=2500) == [old]
    assert not old.exists() and middle.exists() and new.exists()
    assert codegen.trim_cache(max_bytes=2500) == []  # under the cap: nothing more goes


def test_libraries_in_use_are_never_evicted(cache):
    in_use = _library(cache, "in_use", 1000, used_s_ago=1)  # stamped just before loading, elsewhere
    old = _library(cache, "old", 1000, used_s_ago=3600)
    kept = _library(cache, "kept", 1000, used_s_ago=7200)
    assert codegen.trim_cache(max_bytes=0, keep=kept) == [old]
    assert in_use.exists() and kept.exists()
    assert codegen.use_library(old) is False  # gone: the loader builds it again


def test_a_build_over_the_cap_removes_the_oldest_and_keeps_its_own(cache, monkeypatch):
    old = _library(cache, "old", 3000, used_s_ago=3600)
    monkeypatch.setenv("THERMO_DDP_CACHE_MAX_MB", "0.001")  # 1000 bytes: less than any library
    x = ca.SX.sym("x")
    fn = ca.Function("cache_probe", [x], [2 * x])
    assert float(codegen.compiled(fn)(3.0)) == 6.0
    built = codegen.library_path({"cache_probe": fn})
    assert not old.exists() and built.exists()


def test_use_stamps_the_access_time_and_keeps_the_build_time(cache):
    lib = _library(cache, "lib", 10, used_s_ago=3600)
    built = lib.stat().st_mtime_ns
    assert codegen.use_library(lib)
    assert lib.stat().st_mtime_ns == built and lib.stat().st_atime_ns > built + 3000 * 10**9


def test_cache_info_prints_folder_entries_and_size(cache, capsys):
    _library(cache, "a", 1_500_000, used_s_ago=10)
    _library(cache, "b", 500_000, used_s_ago=10)
    assert main(["cache", "--info"]) == 0
    out = capsys.readouterr().out
    assert f"cache folder: {cache}" in out and "libraries: 2" in out and "size: 2.0 MB (cap 2000 MB" in out


def test_clear_removes_only_the_cache_folders_libraries(cache, capsys):
    libs = [_library(cache, n, 100, used_s_ago=5) for n in ("a", "b")]
    index = cache / "ddp_passes_0123.txt"
    index.write_text(f"{libs[0].name} step f")
    foreign = cache / "notes.txt"
    foreign.write_text("not ours")
    outside = cache.parent / f"outside_{'0' * 20}.so"
    outside.write_bytes(b"x")
    assert main(["cache", "--clear"]) == 0
    assert f"removed 3 files from {cache}" in capsys.readouterr().out
    assert sorted(p.name for p in cache.iterdir()) == ["notes.txt"]
    assert outside.exists()


def test_bad_cap_is_one_line_exit_2(cache, monkeypatch, capsys):
    monkeypatch.setenv("THERMO_DDP_CACHE_MAX_MB", "lots")
    assert main(["cache"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "THERMO_DDP_CACHE_MAX_MB = lots" in err
