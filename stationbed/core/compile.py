"""casadi Functions -> C -> shared library, cached on disk by a hash of the generated code.

DESIGN §9: one right-hand side is a few hundred flops; what costs is Python at every call
boundary. So every hot function is generated as C, compiled once with the system compiler
(``cc``/``gcc``; ``$CC`` wins), cached in ``$STATIONBED_CACHE`` (default
``~/.cache/stationbed``) under the SHA-256 of its source, and loaded with ``casadi.external``.
With no compiler (or ``STATIONBED_NO_COMPILE=1``) the SX functions run in casadi's virtual
machine instead: same numbers, slower.

:class:`FastCall` wraps a Function in ``Function.buffer()`` with preallocated numpy inputs and
outputs: a call is then ~0.1 µs of overhead instead of ~35 µs for ``f(numpy...)``.
"""

from __future__ import annotations

import hashlib
import logging
import os
import platform
import re
import shutil
import stat
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from . import progress

__all__ = ["compile_functions", "FastCall", "cache_dir", "compiler", "sx_function", "closed_parametric", "EVALUATOR_C",
           "EVALUATOR_VM"]


def sx_function(name: str, inputs: list, outputs: list, *, called: bool = False) -> ca.Function:
    """An SX Function with common-subexpression elimination.

    The model builds the same quantities in several places (array kinematics for the momentum
    and for the joint drives, ω for the RHS and the extra states); casadi's ``cse`` shares them:
    15-30 % fewer operations per RHS (measured: 1017 -> 865 momentum, 1663 -> 1191 dalembert on
    iss_lvlh_hold), identical values.

    ``called=True`` keeps the function whole where another SX function calls it (casadi's
    ``never_inline``): the caller's graph and generated C hold a call to it, not a copy of its
    operations. A DOP853 step evaluates the RHS 13 times (16 with dense output): inlined, the
    generated C grows with 29 copies of an RHS that grows with the arrays, and the C compiler's
    time faster still (16 arrays: 1.7 MB of C, 51 s; called: 0.43 MB, 6 s; 48 arrays: 185 s ->
    22 s, ``benchmarks/bench_compile.py``). Same operations in the same order: bit-identical.
    """
    return ca.Function(name, inputs, outputs, {"cse": True, "never_inline": called})

#: every build (issue 25, docs/design.md "The compiled tick: compiler flags"): ``-fno-semantic-
#: interposition`` lets gcc inline casadi's small helpers (``casadi_sq``, ``casadi_fabs``,
#: ``casadi_copy`` are exported, so with ``-fPIC`` alone each is a call through the PLT: ~250 per
#: tick of iss_lvlh_hold); ``-ffp-contract=off`` forbids fused multiply-adds, so a build with
#: the machine's own instructions gives the same bits as a portable one (and as the per-tick and
#: lockstep paths: every test comparing paths bit for bit keeps holding); ``-fno-plt`` calls
#: libm's sin, cos, atan2 (~100 a tick) through the GOT without the PLT's jump (5 %). Not
#: ``-ffast-math``: the NaN checks of the executors need IEEE semantics. ``-O3``: 0.92-0.93x the
#: held-environment fused chunk, 0.97x the every-stage one (60 interleaved repeats each), the
#: same bits, and the same compile time for a 16-array DOP853 system (13.1 s / 13.6 s).
#: ``-fno-tree-slp-vectorize``: gcc 12's straight-line vectoriser fuses an add/sub pair of products
#: into ``vfmaddsub`` on AVX-512 machines even with ``-ffp-contract=off`` (4-6 fused instructions
#: in a fused loop's library: its numbers then differed from casadi's evaluator and from a
#: portable build at round-off, docs/design.md "The compiled tick: compiler flags"); without it
#: no library here has a fused instruction (tests/test_compile_flags.py disassembles the fused
#: loops' libraries to check), and loops are still vectorised.
CFLAGS = ["-O3", "-fPIC", "-shared", "-fno-math-errno", "-fno-semantic-interposition", "-ffp-contract=off", "-fno-plt",
          "-fno-tree-slp-vectorize"]
#: tried first: the build machine's own instruction set (AVX...), 10 % of a tick; the library's
#: name is then keyed by the machine (:func:`_machine_key`), so a cache shared with another CPU
#: builds its own; a compiler that refuses the flag builds with :data:`CFLAGS` alone
NATIVE_CFLAGS = ["-march=native"]
#: the minimal flags, the last resort of a compiler that refuses the others
BASE_CFLAGS = ["-O2", "-fPIC", "-shared", "-fno-math-errno", "-ffp-contract=off"]

#: environment variables: the cache folder, and a switch that forces casadi's evaluator
CACHE_ENV = "STATIONBED_CACHE"
NO_COMPILE_ENV = "STATIONBED_NO_COMPILE"
#: library names keep at most this much of the tag (a structure key grows with the arrays; 255
#: bytes is the usual file-name limit); a longer tag is cut and a hash of the whole added
MAX_TAG_CHARS = 64
#: what runs the equations: generated C, or casadi's virtual machine (same numbers, ~10x slower)
EVALUATOR_C = "compiled C"
EVALUATOR_VM = "casadi virtual machine"

log = logging.getLogger("stationbed")
_SAID: set[str] = set()


def _say_once(msg: str) -> None:
    """A warning that the user sees once per process (not once per compiled function)."""
    if msg not in _SAID:
        _SAID.add(msg)
        log.warning(msg)


def cache_dir() -> Path | None:
    """The compile cache folder (``$STATIONBED_CACHE``, default ``~/.cache/stationbed``), or None
    when it cannot be used safely: not a folder, cannot be created or written, or writable by
    other users (a library planted there would be loaded into this process: refused, as ssh
    refuses key files others can write). The reason is said once; the run falls back to
    casadi's evaluator."""
    env = os.environ.get(CACHE_ENV)
    d = Path(env) if env else Path.home() / ".cache" / "stationbed"
    where = f"{CACHE_ENV}={d}" if env else f"the compile cache {d} (the default when {CACHE_ENV} is unset)"
    fallback = f"running without compiled code ({EVALUATOR_VM}: same numbers, slower)"
    try:
        if d.exists() and not d.is_dir():
            _say_once(f"{where} is not a folder; {fallback}")
            return None
        d.parent.mkdir(parents=True, exist_ok=True)
        d.mkdir(mode=0o700, exist_ok=True)
        st = d.stat()
    except OSError as e:
        _say_once(f"{where} cannot be created ({e.strerror}); {fallback}")
        return None
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH) or st.st_uid != os.geteuid():
        _say_once(
            f"{where} is writable by other users (mode {stat.S_IMODE(st.st_mode):o}, owner uid {st.st_uid}): "
            f"refused, a library planted there would run in this process; `chmod go-w {d}` or point "
            f"{CACHE_ENV} at a folder of your own; {fallback}"
        )
        return None
    if not os.access(d, os.W_OK | os.X_OK):
        _say_once(f"{where} is not writable; {fallback}")
        return None
    return d


def compiler() -> str | None:
    """The C compiler to use (``$CC``, ``cc``, ``gcc`` or ``clang``), or None (also when
    ``$STATIONBED_NO_COMPILE`` is set)."""
    if os.environ.get(NO_COMPILE_ENV):
        return None
    for cc in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


_MACHINE: list[tuple[str, bool]] = []  # (key, whether the CPU's flags were read), once per process


def _machine() -> tuple[str, bool]:
    if not _MACHINE:
        flags = ""
        try:
            with open("/proc/cpuinfo") as f:
                flags = next((ln for ln in f if ln.startswith(("flags", "Features"))), "")
        except OSError:
            pass
        words = sorted(flags.partition(":")[2].split())
        _MACHINE.append((f" {platform.machine()} {platform.processor()} {' '.join(words)}", bool(words)))
    return _MACHINE[0]


def _machine_key() -> str:
    """What a ``-march=native`` library depends on: the architecture and the CPU's instruction
    set extensions (the ``flags`` line of ``/proc/cpuinfo``). Two machines with the same key run
    each other's libraries; read once per process."""
    return _machine()[0]


def _native() -> list[str]:
    """:data:`NATIVE_CFLAGS` where the CPU's instruction-set flags are known (Linux
    ``/proc/cpuinfo``): only then does the library's name tell two CPUs apart; elsewhere none
    (a portable build)."""
    return NATIVE_CFLAGS if _machine()[1] else []


#: casadi's min/max helpers as generated, and as built here: casadi calls C99's ``fmax``/``fmin``
#: (a libm call each, ~160 per tick of iss_lvlh_hold: 13 % of it) unless the C is older than
#: C99, where it writes the comparison; this chooses casadi's own comparison for every standard
_MIN_MAX_GUARD = "#if __STDC_VERSION__ < 199901L"


def inline_min_max(src: str) -> str:
    """``src`` with casadi's ``casadi_fmax``/``casadi_fmin`` as a comparison (``x>y ? x : y``,
    casadi's own pre-C99 branch) instead of a call of libm's ``fmax``/``fmin``.

    Same value for every pair of numbers (the sign of a zero aside: ``fmax(-0., 0.)`` may be
    either); where one argument is NaN, libm's returns the other, the comparison returns ``y``
    (so a NaN in ``y`` travels on to the state, where the executors' checks see it).
    """
    for name in ("fmax", "fmin"):
        head = f"casadi_real casadi_{name}(casadi_real x, casadi_real y) {{\n/* Pre-c99 compatibility */\n"
        src = src.replace(head + _MIN_MAX_GUARD, head + "#if 1 /* stationbed: the comparison, not a libm call */")
    return src


#: a read of input k's entry j in casadi's SX code: ``arg[k]? arg[k][j] : 0`` (a null input is zeros)
_INPUT_READ = re.compile(r"arg\[(\d+)\]\? arg\[\1\]\[(\d+)\] : 0")
#: the first line of a generated function (its body follows, up to the next one)
_FUNCTION_HEAD = re.compile(r"^(static int casadi_f\d+\(const casadi_real\*\* arg, [^\n]*\{\n)", re.M)


def hoist_inputs(src: str) -> str:
    """``src`` with each generated function's null-input test made once per input, not per read.

    casadi's SX code reads input k's entry j as ``arg[k]? arg[k][j] : 0`` (a null input means
    zeros): a branch per read, ~1100 in the flight loop's tick, and gcc then duplicates blocks
    across those branches so that most ``sin(x)``/``cos(x)`` pairs land on different paths and
    stay two libm calls instead of one ``sincos`` (docs/design.md "The compiled tick: compiler
    flags"). Here each function reads ``sb_in<k>[j]`` from one pointer set at its top,
    ``arg[k] ? arg[k] : sb_zeros``: the same numbers (the same reads, and glibc's ``sincos`` gives
    what its ``sin`` and ``cos`` give), a null input still read as zeros.
    """
    parts = _FUNCTION_HEAD.split(src)
    out, longest = [parts[0]], 0
    for head, body in zip(parts[1::2], parts[2::2]):
        reads = _INPUT_READ.findall(body)
        if reads:
            longest = max(longest, max(int(j) for _, j in reads) + 1)
            body = _INPUT_READ.sub(lambda m: f"sb_in{m.group(1)}[{m.group(2)}]", body)
            body = "".join(f"  const casadi_real *sb_in{k} = arg[{k}] ? arg[{k}] : sb_zeros;\n"
                           for k in sorted({int(k) for k, _ in reads})) + body
        out += [head, body]
    src = "".join(out)
    if longest:
        zeros = f"static const double sb_zeros[{longest}] = {{0}};\n"
        head = "#include <math.h>\n"
        src = src.replace(head, head + "\n" + zeros, 1) if head in src else zeros + src
    return src


def _file_tag(tag: str) -> str:
    if len(tag) <= MAX_TAG_CHARS:
        return tag
    return f"{tag[: MAX_TAG_CHARS - 13]}_{hashlib.sha256(tag.encode()).hexdigest()[:12]}"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _verified(lib: Path, sig: Path) -> bool:
    """The library exists and its bytes match the digest written when it was built (a file cut
    short or overwritten would crash or fail inside dlopen: it is rebuilt instead)."""
    try:
        return lib.is_file() and sig.is_file() and sig.read_text().strip() == _sha256(lib)
    except OSError:
        return False


def _build(cc: str, src: str, lib: Path, sig: Path, tag: str) -> str | None:
    """Compile ``src`` into ``lib`` and write its digest; returns the reason on failure.

    The user sees ``stationbed: compiling <tag> ...`` once per build (INFO on the
    ``"stationbed"`` logger, which :func:`stationbed.core.progress.configure` shows), then the
    compile as a transient progress task (a bar or heartbeat lines while ``cc`` runs)."""
    log.info(f"compiling {_file_tag(tag)} ...")
    try:
        with tempfile.TemporaryDirectory(dir=lib.parent) as tmp:
            c_file = Path(tmp) / "gen.c"
            c_file.write_text(src)
            tmp_lib = Path(tmp) / "gen.so"
            with progress.task(f"compiling {_file_tag(tag)}", transient=True):
                for flags in (CFLAGS + _native(), CFLAGS, BASE_CFLAGS):  # the first the compiler takes
                    res = subprocess.run([cc, *flags, "-o", str(tmp_lib), str(c_file), "-lm"], capture_output=True, text=True)
                    if res.returncode == 0:
                        break
            if res.returncode != 0:
                first = (res.stderr.strip().splitlines() or ["no message"])[0]
                return f"the C compiler {cc} failed ({first})"
            tmp_sig = Path(tmp) / "gen.sha256"
            tmp_sig.write_text(_sha256(tmp_lib) + "\n")
            os.replace(tmp_lib, lib)  # atomic: concurrent workers never see half a file
            os.replace(tmp_sig, sig)
    except OSError as e:
        return f"cannot write the compiled library to {lib.parent} ({e.strerror}; {CACHE_ENV} names the cache folder)"
    return None


def compile_functions(functions: list[ca.Function], tag: str, extra_c: str = "") -> dict:
    """Compile ``functions`` into one library; return name -> callable casadi Function.

    ``extra_c`` is appended to the generated source (a driver that calls the generated
    functions by name). The result also holds ``"__evaluator__"`` (:data:`EVALUATOR_C` or
    :data:`EVALUATOR_VM`) and, when a library was loaded, its path under ``"__lib__"``. A
    library whose digest does not match is rebuilt; a missing compiler, an unusable cache or a
    failed build fall back to casadi's evaluator (said once, never an error).
    """
    vm = {f.name(): f for f in functions}
    vm["__evaluator__"] = EVALUATOR_VM
    cc = compiler()
    if cc is None:
        why = f"{NO_COMPILE_ENV} is set" if os.environ.get(NO_COMPILE_ENV) else "no C compiler (cc, gcc or clang) found"
        _say_once(f"{why}: running without compiled code ({EVALUATOR_VM}: same numbers, ~10x slower)")
        return vm
    d = cache_dir()
    if d is None:
        return vm
    cg = ca.CodeGenerator(f"sb_{tag}.c", {"with_header": False})
    for f in functions:
        cg.add(f)
    src = hoist_inputs(inline_min_max(cg.dump())) + extra_c
    key = " ".join(CFLAGS + _native()) + _machine_key()
    digest = hashlib.sha256((src + key).encode()).hexdigest()[:20]
    lib = d / f"sb_{_file_tag(tag)}_{digest}.so"
    sig = lib.with_name(lib.name + ".sha256")
    for attempt in range(2):
        if not _verified(lib, sig):
            if sig.exists() and lib.exists() and attempt == 0:  # (no digest yet: another process is building it)
                _say_once(f"cached library {lib} does not match its digest: rebuilding it")
            reason = _build(cc, src, lib, sig, tag)
            if reason is not None:
                _say_once(f"{reason}; running without compiled code ({EVALUATOR_VM}: same numbers, slower)")
                return vm
        try:
            funcs = {f.name(): ca.external(f.name(), str(lib)) for f in functions}
        except RuntimeError as e:  # a verified file that still does not load: rebuild once
            sig.unlink(missing_ok=True)
            if attempt == 1:
                _say_once(f"cannot load {lib} ({str(e).splitlines()[0]}); running with {EVALUATOR_VM}")
                return vm
            continue
        funcs["__lib__"] = str(lib)
        funcs["__evaluator__"] = EVALUATOR_C
        return funcs
    return vm  # pragma: no cover - the loop returns


def _dense(f: ca.Function) -> ca.Function:
    """``f`` itself when every input and output is dense, else a wrapper with dense ones.

    A casadi buffer reads and writes only the *nonzeros* of an argument or result: an output
    with structural zeros (the LVLH outputs of a deep-space measurement, say) fills the first
    nnz entries of a dense numpy array, every value after the first zero shifted. The wrapper
    (an MX call of ``f``, same compiled code, densified results) keeps the dense layout every
    reader of :attr:`FastCall.res` assumes."""
    dense = all(f.sparsity_in(i).is_dense() for i in range(f.n_in())) and all(
        f.sparsity_out(j).is_dense() for j in range(f.n_out()))
    if dense:
        return f
    xs = [ca.MX.sym(f.name_in(i), f.size_in(i)) for i in range(f.n_in())]
    ys = f.call(xs)
    return ca.Function(f.name() + "_dense", xs, [ca.densify(y) for y in ys], f.name_in(), f.name_out())


class FastCall:
    """Zero-copy repeated calls of a casadi Function with dense inputs/outputs.

    ``fc.args[i]`` and ``fc.res[j]`` are numpy arrays bound to the function; write inputs in
    place (``fc.args[0][:] = x``), call ``fc()``, read outputs.
    """

    def __init__(self, f: ca.Function):
        self.f = f
        self.args = [np.zeros(f.numel_in(i)) for i in range(f.n_in())]
        self.res = [np.zeros(f.numel_out(i)) for i in range(f.n_out())]
        self._buf, self._trigger = _dense(f).buffer()
        for i, a in enumerate(self.args):
            self._buf.set_arg(i, memoryview(a))
        for j, r in enumerate(self.res):
            self._buf.set_res(j, memoryview(r))

    def __call__(self):
        self._trigger()

    @property
    def trigger(self):
        """The bound buffer's trigger: one C call, no Python wrapper (hot loops keep it)."""
        return self._trigger

    _cache: dict = {}

    @classmethod
    def of(cls, f: ca.Function) -> "FastCall":
        """A shared FastCall per Function (buffers reused across runs; not thread-safe)."""
        key = id(f)
        hit = cls._cache.get(key)
        if hit is None or hit.f is not f:
            hit = cls._cache[key] = cls(f)
        return hit


def closed_parametric(vals: list, syms: list) -> list:
    """``extract_parametric``'s values written in the carry and parameters alone: casadi may give
    a value in terms of other extracted symbols (seen on the Hamel form with flexible arrays:
    ``cl_pre`` then had a free symbol); substituted until none is left (at most ``len(syms)``
    rounds: each round resolves one more level of nesting). A value without such a symbol, the
    usual case, is returned as it is (same graph, same generated code)."""
    if not syms:
        return vals
    every = ca.vertcat(*syms)
    for _ in range(len(syms)):
        if not any(ca.depends_on(v, every) for v in vals):
            return vals
        vals = ca.substitute(vals, syms, vals)
    raise AssertionError("extract_parametric's values still depend on its symbols")
