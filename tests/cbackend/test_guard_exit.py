"""The host process survives its own exit: pythonfmu 0.7.0's exit-time use-after-free is defused.

pythonfmu's native library cannot be unloaded (STB_GNU_UNIQUE symbols), so it is still there
when the host exits; its static destructors then run before its ELF destructor
``finalizePythonInterpreter``, which releases an already destroyed shared_ptr again. At random
(it depends on the heap layout, e.g. on the FMU's content hash) glibc aborted the host at exit
with "corrupted double-linked list" (seen in the interop runs). The native guard now empties
that shared_ptr while it is alive (fmi2_guard.c). valgrind sees the invalid access every time,
so the test runs the host under valgrind (skipped where valgrind is not installed).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap

import pytest

pytestmark = [pytest.mark.skipif(shutil.which("valgrind") is None, reason="needs valgrind"), pytest.mark.schedule_first]
# Memcheck without its definedness tracking (about a quarter faster here): the use-after-free is an
# access to a freed block, which its addressability checks report whatever this setting
VALGRIND_FAST = ["--undef-value-errors=no"]


@pytest.mark.parametrize("guarded", [True, False], ids=["native-guard", "python-only"])
def test_no_use_after_free_in_pythonfmu_at_host_exit(fmu_dir, design_speed, tmp_path, guarded, monkeypatch):
    """With the guard (fmi2_guard.c) and without it (framework.py's Python exit handler)."""
    if guarded:
        fmu = fmu_dir / "SideslipBankObserver.fmu"
    else:
        from latobs import native_guard, packaging
        from latobs.synthesis import design_file
        monkeypatch.setattr(native_guard, "find_compiler", lambda: None)
        with pytest.warns(UserWarning, match="no native guard"):
            fmu = packaging.package_design(design_file.write(design_speed, tmp_path), tmp_path)
    script = tmp_path / "host.py"
    script.write_text(textwrap.dedent("""
        import sys
        from fmpy import simulate_fmu
        for _ in range(2):                      # load, run, unload, reload
            simulate_fmu(sys.argv[1], stop_time=0.02, step_size=0.01, output_interval=0.01)
    """))
    env = dict(os.environ, PYTHONMALLOC="malloc")     # every allocation visible to valgrind
    proc = subprocess.run(["valgrind", "--error-limit=no", *VALGRIND_FAST, sys.executable, str(script),
                           str(fmu)],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = proc.stderr
    assert "finalizePythonInterpreter" not in report, report[report.find("finalizePythonInterpreter") - 2000:][:4000]
    assert "Invalid write" not in report
