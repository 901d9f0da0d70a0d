"""An FMU state is tied to its FMU (issue 47, item 3).

A native FMU's state (``fmu_src/c/layer.h``), in memory and serialised, carries a hash of its
FMU's instantiation token, its layer (FMI 2.0 or 3.0), the platform's layout, its size and a
checksum; every FMU-state call reads a given state only as far as it has checked it. Before, the
FMI 2.0 and 3.0 layers took CarPlant's 2.2 KB state into LateralIntervalObserver (137 KB) with
fmi2OK, reading past the block, and a serialised state whose second half is 0xFF with fmi2OK
(every later output NaN).

* A plain C host (``tests/c_host/state_host.c``) loads CarPlant and LateralIntervalObserver,
  FMI 2.0 and 3.0, each twice (an instance and its untouched twin): every FMU's state into every
  other's six state calls, and each FMU's own serialisation truncated, extended, with its second
  half 0xFF, a one-bit flip at every header bit and at random bits, random mutations, and a bit
  flipped in memory: each refused (status >= error), the instance's outputs bit-identical to its
  twin's after the refusals and for 40 more steps. It runs on the shipped binaries, under valgrind
  on them, and against the FMUs' shipped sources compiled with AddressSanitizer and UBSan (each
  skipped with one line where the tool is missing).
* Through fmpy: a forged state with a valid checksum but a NaN time or an impossible phase, a
  ModelExchange state given to a co-simulation instance, and the pythonfmu FMUs (whose guard
  refuses every state call) given native states and their damaged bytes: refused, state kept.
"""
from __future__ import annotations

import ctypes
import math
import re
import shlex
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import pytest
from fmpy import extract, read_model_description

from conftest import fmpy_callbacks
from latobs.native_guard import find_compiler, fmi2_headers

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC, or install cc/gcc)")]
HOST = Path(__file__).resolve().parents[1] / "c_host" / "state_host.c"
NAMES = ("CarPlant", "LateralIntervalObserver")
DT = 0.005
SANITIZERS = "-fsanitize=address,undefined"


# ---- the C host -----------------------------------------------------------------------------------

def _cc(*args: str, out: Path) -> None:
    proc = subprocess.run([*shlex.split(find_compiler()), *args, "-o", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]


def _host(tmp: Path, sanitized: bool) -> Path:
    exe = tmp / ("state_host_asan" if sanitized else "state_host")
    flags = ["-fsanitize=address,undefined", "-fno-omit-frame-pointer"] if sanitized else []
    _cc("-std=c99", "-D_POSIX_C_SOURCE=200809L", "-O1", "-g", "-Wall", "-Wextra", "-Werror", *flags,
        f"-I{fmi2_headers()}", str(HOST), "-ldl", "-lm", out=exe)
    return exe


def _sanitizers_work(tmp: Path) -> str | None:
    """None when the C compiler builds and runs an AddressSanitizer program here, else why not."""
    src = tmp / "probe.c"
    src.write_text("#include <stdlib.h>\nint main(void) { char *p = malloc(4); p[0] = 1; free(p); return 0; }\n")
    proc = subprocess.run([*shlex.split(find_compiler()), SANITIZERS, str(src), "-o", str(tmp / "probe")],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        return f"the C compiler cannot build with {SANITIZERS}: {proc.stderr.strip()[-200:]}"
    run = subprocess.run([str(tmp / "probe")], capture_output=True, text=True)
    return None if run.returncode == 0 else f"AddressSanitizer programs do not run here: {run.stderr.strip()[-200:]}"


@pytest.fixture(scope="module")
def native(built_fmus):
    """{(name, FMI version): FMU path}: the session build's native FMUs, FMI 2.0 and 3.0."""
    return {(n, v): built_fmus.c3_path(n) if v == 3 else built_fmus.c_path(n) for n in NAMES for v in (2, 3)}


def _host_args(native: dict, tmp: Path, sanitized: bool) -> list[str]:
    """The host's 8 arguments per FMU; its library the shipped binary, or (``sanitized``) its
    shipped sources compiled with the sanitizers."""
    args = []
    for (name, version), fmu in sorted(native.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        folder = tmp / f"{name}-fmi{version}"
        with zipfile.ZipFile(fmu) as z:
            z.extractall(folder)
        md = read_model_description(str(folder / "modelDescription.xml"))
        lib = folder / "binaries" / ("linux64" if version == 2 else "x86_64-linux") / f"{name}.so"
        if sanitized:       # (-O0: LateralIntervalObserver's sources compile in 4 s, 14 s at -O1)
            lib = folder / f"{name}-asan.so"
            sources = sorted(str(p) for p in (folder / "sources").glob("*.c"))
            _cc("-std=c99", "-O0", "-g", "-fPIC", "-shared", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror",
                SANITIZERS, "-fno-omit-frame-pointer", f"-I{folder / 'sources'}", *sources, "-lm", out=lib)
        variables = md.modelVariables
        ins = [v for v in variables if v.causality == "input"]
        reals = [v.valueReference for v in variables if v.causality == "output" and v.type in ("Real", "Float64")]
        ints = [v.valueReference for v in variables if v.causality == "output" and v.type not in ("Real", "Float64")]
        joined = lambda xs: ",".join(map(str, xs)) or "-"     # noqa: E731
        args += [str(version), str(lib), name, md.guid, joined(v.valueReference for v in ins),
                 joined(float(v.start) for v in ins), joined(reals), joined(ints)]
    return args


def _check_host_output(proc: subprocess.CompletedProcess) -> str:
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "state_host: 0 failure(s)" in out, out[-6000:]
    assert "FAIL" not in out
    return out


def test_a_state_of_another_fmu_or_damaged_is_refused_and_the_state_kept(native, tmp_path):
    """The issue's reproductions on the shipped binaries, with the messages a user reads."""
    exe = _host(tmp_path, sanitized=False)
    proc = subprocess.run([str(exe), "400", "6", "1", *_host_args(native, tmp_path, False)], capture_output=True,
                          text=True, timeout=300)
    out = _check_host_output(proc)
    msg = {line.split(": ", 1)[0]: line.split(": ", 1)[1] for line in out.splitlines() if line.startswith("msg ")}
    assert msg["msg set CarPlant (FMI 2) -> LateralIntervalObserver (FMI 2)"].startswith(
        "fmi2SetFMUstate: state refused: it is a state of another FMU, CarPlant (")
    assert "the instance's state is kept" in msg["msg set CarPlant (FMI 2) -> LateralIntervalObserver (FMI 2)"]
    assert msg["msg set LateralIntervalObserver (FMI 3) -> CarPlant (FMI 3)"].startswith(
        "fmi3SetFMUState: state refused: it is a state of another FMU, LateralIntervalObserver (")
    assert "a state of CarPlant's FMI 2.0 FMU, this is its FMI 3.0 FMU" in msg["msg set CarPlant (FMI 2) -> CarPlant (FMI 3)"]
    assert "fmi2DeSerializeFMUstate: serialised state refused: it is a state of another FMU, CarPlant" in \
        msg["msg deserialize CarPlant (FMI 2) -> LateralIntervalObserver (FMI 2)"]
    truncated = re.search(r"it is truncated \((\d+) bytes, (\d+) expected\)", msg["msg truncated LateralIntervalObserver (FMI 2)"])
    assert truncated and int(truncated.group(1)) == int(truncated.group(2)) // 2, msg   # the host cuts it in half
    for version in (2, 3):
        for name in NAMES:
            assert "it is corrupted (its checksum does not match" in msg[f"msg ffhalf {name} (FMI {version})"]
            assert "it is corrupted" in msg[f"msg memflip {name} (FMI {version})"]
    assert "it is not a state of a latobs FMU (a pointer this FMU never handed out" in \
        msg["msg junk LateralIntervalObserver (FMI 3)"]
    # every check ran: 4 x 3 ordered pairs x 9 checks, 4 x 8 damaged-state checks, 4 + 4 runs
    assert out.count("\nok   ") + out.startswith("ok   ") == 4 * 3 * 9 + 4 * 8 + 8


def test_the_state_calls_under_address_sanitizer_read_nothing_outside_a_state(native, tmp_path):
    """The FMUs' shipped sources and the host built with AddressSanitizer and UBSan: thousands of
    foreign, truncated and mutated states (a few seconds), no read or write outside a block."""
    why = _sanitizers_work(tmp_path)
    if why:
        pytest.skip(why)
    exe = _host(tmp_path, sanitized=True)
    proc = subprocess.run([str(exe), "3000", "6", "2", *_host_args(native, tmp_path, True)], capture_output=True,
                          text=True, timeout=300, env={"PATH": "/usr/bin:/bin", "ASAN_OPTIONS": "detect_leaks=1",
                                                       "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1"})
    out = _check_host_output(proc)
    assert "AddressSanitizer" not in out and "runtime error" not in out, out[-6000:]


def test_the_state_calls_under_valgrind_read_nothing_outside_a_state(native, tmp_path):
    """The shipped binaries under valgrind's memcheck: before, CarPlant's state into
    LateralIntervalObserver read 135 KB past its block."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        pytest.skip("valgrind is not installed")
    exe = _host(tmp_path, sanitized=False)
    proc = subprocess.run([valgrind, "--error-exitcode=99", "--leak-check=no", str(exe), "60", "20", "3",
                           *_host_args(native, tmp_path, False)], capture_output=True, text=True, timeout=600)
    out = _check_host_output(proc)
    assert "Invalid read" not in out and "Invalid write" not in out, out[-6000:]


# ---- through fmpy ---------------------------------------------------------------------------------

class Logged:
    """The messages of every instance (fmpy's proxy hands them all to the last logger registered:
    one for the process), by instance name."""

    def __init__(self):
        self.messages: list[tuple[str, int, str]] = []

    def __call__(self, component, instance, status, category, message):
        text = message.decode() if isinstance(message, bytes) else str(message)
        self.messages.append((instance.decode() if isinstance(instance, bytes) else str(instance), status, text))

    def last_error(self, instance: str) -> str:
        return next((m for i, s, m in reversed(self.messages) if s >= 3 and i == instance), "")


LOG = Logged()


class Running:
    """An FMI 2.0 co-simulation instance of ``fmu``, initialised, its inputs near their starts."""

    def __init__(self, fmu: Path, tmp: Path, label: str, model_exchange: bool = False):
        from fmpy.fmi2 import FMU2Model, FMU2Slave

        self.md = read_model_description(str(fmu))
        unzipped = extract(str(fmu), unzipdir=str(tmp / label))
        cls, ident = (FMU2Model, self.md.modelExchange) if model_exchange else (FMU2Slave, self.md.coSimulation)
        self.label = label
        self.fmu = cls(guid=self.md.guid, unzipDirectory=unzipped, modelIdentifier=ident.modelIdentifier,
                       instanceName=label)
        self.fmu.instantiate(callbacks=fmpy_callbacks(LOG), loggingOn=True)   # (pythonfmu: else silent)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        variables = self.md.modelVariables
        self.inputs = [(v.valueReference, float(v.start)) for v in variables if v.causality == "input"]
        self.reals = [v.valueReference for v in variables if v.causality == "output" and v.type == "Real"]
        self.ints = [v.valueReference for v in variables if v.causality == "output" and v.type == "Integer"]
        self.t = 0.0
        self.raw = self.fmu._functions
        self.c = self.fmu.component

    def last_error(self) -> str:
        return LOG.last_error(self.label)

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.fmu.setReal([vr for vr, _ in self.inputs],
                             [x + 0.01 * max(1.0, abs(x)) * math.sin(3.0 * self.t + i)
                              for i, (_, x) in enumerate(self.inputs)])
            self.fmu.doStep(self.t, DT)
            self.t += DT

    def outputs(self) -> bytes:
        return struct.pack(f"{len(self.reals)}d", *self.fmu.getReal(self.reals)) + \
            struct.pack(f"{len(self.ints)}i", *self.fmu.getInteger(self.ints))

    def get_state(self):
        from fmpy.fmi2 import fmi2FMUstate

        state = fmi2FMUstate()
        assert self.raw["fmi2GetFMUstate"](self.c, ctypes.byref(state)) == 0
        return state

    def serialized(self, state) -> bytes:
        size = ctypes.c_size_t()
        assert self.raw["fmi2SerializedFMUstateSize"](self.c, state, ctypes.byref(size)) == 0
        buf = ctypes.create_string_buffer(size.value)
        assert self.raw["fmi2SerializeFMUstate"](self.c, state, buf, size.value) == 0
        return buf.raw

    def deserialize(self, data: bytes) -> tuple[int, int]:
        """(status, the state pointer made: 0 if none)"""
        from fmpy.fmi2 import fmi2FMUstate

        state = fmi2FMUstate()
        buf = ctypes.create_string_buffer(data, len(data))
        status = self.raw["fmi2DeSerializeFMUstate"](self.c, buf, len(data), ctypes.byref(state))
        return status, state.value or 0

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def _pair(fmu: Path, tmp: Path, label: str) -> tuple[Running, Running]:
    """An instance and its twin, both stepped 40 times alike."""
    a, b = Running(fmu, tmp, f"{label}-main"), Running(fmu, tmp, f"{label}-twin")
    a.step(40)
    b.step(40)
    assert a.outputs() == b.outputs()
    return a, b


def _still_twins(a: Running, b: Running) -> None:
    assert a.outputs() == b.outputs()
    for _ in range(20):
        a.step()
        b.step()
        assert a.outputs() == b.outputs()


# the documented layout (layer.h): StateHeader (112 bytes, its checksum at 40), then Values
# (int phase, int ready, double time, double p[], ...)
HEADER, CHECKSUM_AT, PRIME, OFFSET, MASK = 112, 40, 0x100000001b3, 0xcbf29ce484222325, (1 << 64) - 1


def _mix(h: int, w: int) -> int:
    h = ((h ^ w) * PRIME) & MASK
    return h ^ (h >> 32)


def _hash_words(h: int, data: bytes) -> int:
    whole = len(data) // 8 * 8
    for (w,) in struct.iter_unpack("<Q", data[:whole]):
        h = _mix(h, w)
    for b in data[whole:]:
        h = _mix(h, b)
    return h


def _checksum(state: bytes) -> int:
    """layer.h's state_checksum, written again from its comments: the header (its checksum 0) in
    one chain of ``mix`` over words, the rest in four interleaved lanes hashed into it."""
    h = _hash_words(OFFSET, state[:CHECKSUM_AT] + bytes(8) + state[CHECKSUM_AT + 8:HEADER])
    body = state[HEADER:]
    whole = len(body) // 32 * 32
    lanes = [h, h ^ 1, h ^ 2, h ^ 3]
    for i, (w,) in enumerate(struct.iter_unpack("<Q", body[:whole])):
        lanes[i % 4] = _mix(lanes[i % 4], w)
    for lane in lanes:
        h = _mix(h, lane)
    return _hash_words(h, body[whole:])


def _forged(state: bytes, at: int, fmt: str, value) -> bytes:
    """``state`` with ``value`` packed at ``at`` and its checksum made right again."""
    out = bytearray(state)
    struct.pack_into(fmt, out, at, value)
    struct.pack_into("<Q", out, CHECKSUM_AT, _checksum(bytes(out)))
    return bytes(out)


def test_a_forged_state_with_a_right_checksum_but_impossible_values_is_refused(built_fmus, tmp_path):
    """Values no instance can hold (a NaN time, an unknown phase, a parameter outside its range
    once initialised) are refused even when the checksum was made to match."""
    a, b = _pair(built_fmus.c_path("CarPlant"), tmp_path, "CarPlant")
    try:
        state = a.get_state()
        good = a.serialized(state)
        assert _checksum(good) == struct.unpack_from("<Q", good, CHECKSUM_AT)[0]    # the format as documented
        assert a.deserialize(_forged(good, HEADER + 8, "<d", 0.25))[0] == 0          # another time: fine
        cases = [(HEADER + 8, "<d", math.nan, "time = nan"), (HEADER + 8, "<d", math.inf, "time = inf"),
                 (HEADER, "<i", 9, "phase 9"), (HEADER + 4, "<i", 0, "ready = 0"),
                 (HEADER + 16, "<d", 99.0, "parameter mu = 99.0 outside its declared range")]
        for at, fmt, value, words in cases:
            status, made = a.deserialize(_forged(good, at, fmt, value))
            assert (status, made) == (3, 0), words
            assert "it holds what this FMU never holds" in a.last_error() and words in a.last_error()
        status, made = a.deserialize(good)
        assert status == 0 and made
        _still_twins(a, b)
        a.raw["fmi2FreeFMUstate"](a.c, ctypes.byref(state))
    finally:
        a.close(), b.close()


def test_a_model_exchange_state_is_refused_by_a_cosimulation_instance(built_fmus, tmp_path):
    fmu = built_fmus.c_path("CarPlant")
    me = Running(fmu, tmp_path, "me", model_exchange=True)
    a, b = _pair(fmu, tmp_path, "cs")
    try:
        from fmpy.fmi2 import fmi2FMUstate

        state = fmi2FMUstate()
        assert me.raw["fmi2GetFMUstate"](me.c, ctypes.byref(state)) == 0
        assert a.raw["fmi2SetFMUstate"](a.c, state) == 3
        assert "it is a state of a ModelExchange instance, this one is CoSimulation" in a.last_error()
        _still_twins(a, b)
        me.raw["fmi2FreeFMUstate"](me.c, ctypes.byref(state))
    finally:
        me.fmu.terminate(), me.fmu.freeInstance(), a.close(), b.close()


def test_a_non_finite_communication_point_is_refused_the_state_kept(built_fmus, tmp_path):
    """The instance's time (part of its state) stays finite: doStep(t = inf or NaN) is refused."""
    for fmu in (built_fmus.c_path("CarPlant"), built_fmus.path("CarPlant")):
        a, b = _pair(fmu, tmp_path, f"t-{len(list(tmp_path.iterdir()))}")
        try:
            for t in (math.inf, math.nan):
                assert a.raw["fmi2DoStep"](a.c, t, DT, 1) in (2, 3)       # pythonfmu: fmi2Discard
                assert "is not finite; state held" in a.last_error()
            _still_twins(a, b)
        finally:
            a.close(), b.close()


def test_a_non_finite_communication_point_is_refused_by_the_fmi3_layer_too(built_fmus, tmp_path):
    from fmpy.fmi3 import FMU3Slave

    fmu = built_fmus.c3_path("CarPlant")
    md = read_model_description(str(fmu))
    errors: list[str] = []

    def log(env, status, category, message):
        if status >= 3:
            errors.append(message.decode())

    s = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu), unzipdir=str(tmp_path / "u")),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="t")
    s.instantiate(loggingOn=True, logMessage=log)
    try:
        s.enterInitializationMode(startTime=0.0)
        s.exitInitializationMode()
        s.doStep(0.0, DT)
        flags = [ctypes.c_bool() for _ in range(3)] + [ctypes.c_double()]
        for t in (math.inf, -math.inf, math.nan):
            status = s._functions["fmi3DoStep"](s.component, t, DT, True, *map(ctypes.byref, flags))
            assert status == 3 and "communication point" in errors[-1] and "is not finite; state held" in errors[-1]
        s.doStep(DT, DT)                                       # a finite one proceeds
    finally:
        s.terminate()
        s.freeInstance()


@pytest.mark.parametrize("target", NAMES)
def test_pythonfmu_fmus_refuse_native_states_and_their_bytes_the_state_kept(built_fmus, tmp_path, target):
    """The pythonfmu FMUs get and set no state (their guard refuses the six calls): a native FMU's
    state (the other model's, as in the issue, and the same model's), its bytes, and those bytes
    truncated, with their second half 0xFF or one bit flipped are each refused, the state kept."""
    other = "CarPlant" if target == "LateralIntervalObserver" else "LateralIntervalObserver"
    a, b = _pair(built_fmus.path(target), tmp_path, f"py-{target}")
    sources = [Running(built_fmus.c_path(n), tmp_path, f"c-{n}") for n in (other, target)]
    try:
        for src in sources:
            src.step(5)
            state = src.get_state()
            data = src.serialized(state)
            assert a.raw["fmi2SetFMUstate"](a.c, state) == 3
            assert "cannot get, set or serialize its state" in a.last_error()
            flipped = bytearray(data)
            flipped[len(data) // 3] ^= 0x10
            for damaged in (data, data[:len(data) // 2], data[:len(data) // 2] + b"\xff" * (len(data) - len(data) // 2),
                            bytes(flipped)):
                assert a.deserialize(damaged) == (3, 0)
            src.raw["fmi2FreeFMUstate"](src.c, ctypes.byref(state))
        _still_twins(a, b)
    finally:
        for r in (a, b, *sources):
            r.close()
