"""latobs's content-addressed cache (``latobs.cache``): paper 001's build-time fact (the longest
communication step, decided by probing the runtime) computed once per design content and reused,
a changed design never served a stale value, an unreadable entry computed again, and
``latobs build --no-cache`` / LATOBS_NO_CACHE deciding everything again."""
from __future__ import annotations

import copy
import os

import pytest

from latobs import cache, packaging
from latobs.fmu_src.lateral_interval_observer import IntervalObserver


def _bare(design):
    d = copy.deepcopy({k: v for k, v in design.items() if k != "tables"})
    del d["runtime"]["max_communication_step"]
    return d


def test_a_build_time_fact_is_decided_once_per_design_content(built_fmus, tmp_path, monkeypatch):
    """The runtime's own decision (its probes) once, then from the cache: the same value; another
    design content decides again; so does an unreadable entry, and a turned-off cache. The probes
    themselves (5 s each) are counted through a stand-in after the first real one."""
    design = built_fmus.design("LateralIntervalObserver")
    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path / "cache"))      # an empty cache
    calls = []
    real = IntervalObserver.build_time_facts.__func__

    def counted(cls, data):
        calls.append(1)
        return real(cls, data) if len(calls) == 1 else {"max_communication_step": 0.25}

    monkeypatch.setattr(IntervalObserver, "build_time_facts", classmethod(counted))
    first = packaging.complete_runtime_data(_bare(design))["runtime"]["max_communication_step"]
    assert first == design["runtime"]["max_communication_step"] and len(calls) == 1
    again = packaging.complete_runtime_data(_bare(design))
    assert again["runtime"]["max_communication_step"] == first and len(calls) == 1     # from the cache
    assert again["tables"]["max_communication_step"] == first
    entries = list((tmp_path / "cache" / "build-time-facts").glob("*.json"))
    assert len(entries) == 1
    # another design (its initial box changed): another key, decided again
    other = _bare(design)
    other["runtime"]["x0_halfwidth"] = [2.0, 0.0, 0.0, 30.0]
    packaging.complete_runtime_data(other)
    assert len(calls) == 2 and len(list((tmp_path / "cache" / "build-time-facts").glob("*.json"))) == 2
    # an unreadable entry: decided again, rewritten
    entries[0].write_text("{ not json")
    assert packaging.complete_runtime_data(_bare(design))["runtime"]["max_communication_step"] == 0.25
    assert len(calls) == 3
    # turned off: decided every time, nothing read
    with cache.turned_off():
        assert os.environ[cache.ENV_OFF] == "1"
        packaging.complete_runtime_data(_bare(design))
    assert len(calls) == 4 and cache.ENV_OFF not in os.environ


def test_an_unwritable_cache_folder_still_computes(tmp_path, monkeypatch):
    (tmp_path / "file").write_text("a file where the cache folder would be")
    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path / "file"))
    assert cache.remember("k", {"a": 1}, lambda: {"x": 1.5}) == {"x": 1.5}


def test_the_default_folder_is_the_users_cache(monkeypatch, tmp_path):
    monkeypatch.delenv(cache.ENV_DIR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache.folder() == tmp_path / "latobs"


@pytest.mark.parametrize("flag", [["--no-cache"], []])
def test_build_no_cache_flag(flag, tmp_path, monkeypatch):
    from latobs.cli import main

    seen = []
    monkeypatch.setattr("latobs.cli._build", lambda args: seen.append(cache.enabled()) or 0)
    assert main(["build", "CarPlant", "--out", str(tmp_path), *flag]) == 0
    assert seen == [not flag] and cache.enabled()
