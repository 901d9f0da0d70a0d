"""Designs solved in parallel processes (``lmi.parallel_map``: paper 002's speed bands, the designs
of one ``latobs build``) are those of the sequential loop, bit for bit; the solver choice of
``lmi.using`` reaches the workers, whose solves its block records; an error of an item is raised
in the caller."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from latobs.synthesis import lmi
from latobs.synthesis import sideslip_fixed_order_estimator as sfo
from latobs.synthesis.params import load_vehicle

pytestmark = pytest.mark.schedule_first      # (few long tests: tests/conftest.py)


def solver_here(_):
    return lmi.current()


def fails_on_two(x):
    if x == 2:
        raise ValueError("item two is refused")
    return x


def test_the_workers_solve_with_the_callers_solver_and_raise_its_errors(monkeypatch):
    monkeypatch.setenv(lmi.JOBS_ENV, "2")
    with lmi.using("SCS"):
        assert lmi.parallel_map(solver_here, [0, 1]) == ["SCS", "SCS"]
    assert lmi.parallel_map(solver_here, [0, 1]) == ["CLARABEL", "CLARABEL"]
    with pytest.raises(ValueError, match="item two"):
        lmi.parallel_map(fails_on_two, [1, 2, 3])
    monkeypatch.setenv(lmi.JOBS_ENV, "0")
    with pytest.raises(ValueError, match="LATOBS_JOBS"):
        lmi.jobs(3)


@pytest.mark.slow
def test_scheduled_bands_in_parallel_equal_the_sequential_design(monkeypatch):
    """Paper 002's scheduled design (Lemma 5 without the polish, certified on a coarse grid, two bands of the paper's car: its 20-40 km/h split once) in
    two processes and in this one: the same estimators and certificates, bit for bit."""
    vehicle = load_vehicle("delibasi")
    opts = dataclasses.replace(sfo.DesignOptions(), name="SideslipFixedOrderEstimatorScheduled_delibasi",
                               scheduled=True, band_ratio=1.5, band_beta_step=10.0, polish=False,
                               grid=(3, 3, 3))
    monkeypatch.setenv(lmi.JOBS_ENV, "2")
    with lmi.using("CLARABEL") as usage:
        parallel = sfo.design_for_vehicle(vehicle, opts)
    assert len(parallel.modes) >= 2 and len(usage.calls) >= len(parallel.modes)   # the workers' solves
    monkeypatch.setenv(lmi.JOBS_ENV, "1")
    sequential = sfo.design_for_vehicle(vehicle, opts)
    assert len(parallel.modes) == len(sequential.modes)
    for a, b in zip(parallel.modes, sequential.modes):
        assert a.box == b.box and a.method == b.method
        for name in ("y", "x"):
            assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
        assert a.certificate.keys() == b.certificate.keys()
        for k, v in a.certificate.items():
            assert np.array_equal(np.asarray(v), np.asarray(b.certificate[k])), k


def test_a_script_without_a_main_guard_is_not_run_again_in_the_workers(tmp_path):
    """A user's script calling latobs at its top level (no ``if __name__ == "__main__"``): the
    workers do not run it again (before, each spawned worker re-ran it and the build hung)."""
    import os
    import subprocess
    import sys

    script = tmp_path / "user_script.py"
    script.write_text("from latobs.synthesis import lmi\n"
                      "print('script ran', flush=True)\n"
                      "print(lmi.parallel_map(abs, [-1, -2, -3]), flush=True)\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, lmi.JOBS_ENV: "2"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == ["script ran", "[1, 2, 3]"], proc.stdout
