"""Kernels compiled at build time and shipped with the package (the linux-x64 extension zip).

numba's cache (``cache=True``) keys a compiled kernel on the content of its source file, its
signature, the Python version and the CPU it was compiled for (LLVM's name of the host CPU and
its feature list), so a cache built on one machine is found only on an identical one.
``make extension`` therefore compiles the kernels for a generic CPU, :data:`GENERIC_CPU`
(``NUMBA_CPU_NAME=x86-64-v3``, ``NUMBA_CPU_FEATURES=""``: AVX2 and FMA, every x86-64 CPU since
2013-2015), runs :mod:`.warmup`, and ships the cache in :data:`SHIPPED`
(mk/build_extension.py). Here each kernel's cache is given a second place to look: when the
user's cache (numba's own lookup, for this CPU) has no entry, the shipped one for the generic
CPU, if this CPU can run that code. Kernels compiled here (signatures the warm-up did not
meet, another CPU) go to the user's cache as before; nothing is written to :data:`SHIPPED`.

Kernels loaded from it are the generic CPU's code, which may differ in the last bits from
code compiled for this CPU where a kernel allows fast-math reassociation (vector widths
differ); docs/performance.md ("First contact: compiling, and the shipped kernels") has the
speed measured.
"""

from __future__ import annotations

import importlib
import io
import os
import pickle
import re
import sys
from pathlib import Path

from numba.core import caching

#: where the shipped cache lives, one directory per source directory of the package
#: (``kernel_cache/core`` for ``core/*.py``). ``$MOEBIUS_KERNEL_CACHE`` names another: ``make
#: test`` points a checkout at the cache its test zip ships, whose index stamps are the
#: checkout's own files' (the build copies them with their times), so the suite loads those
#: kernels instead of compiling them a third time (mk/run_tests.py); a kernel whose source
#: differs from what the cache was built from is compiled as before (numba's stamp check).
SHIPPED = Path(os.environ.get("MOEBIUS_KERNEL_CACHE")
               or Path(__file__).resolve().parents[1] / "kernel_cache").resolve()
PACKAGE_ROOT = Path(__file__).resolve().parents[2]
#: LLVM's name of the CPU the shipped kernels were compiled for
GENERIC_CPU = "x86-64-v3"
#: the x86-64-v3 feature set (x86-64 psABI levels v2 and v3) in LLVM's names
_V3_FEATURES = ("cx16", "sahf", "popcnt", "sse3", "sse4.1", "sse4.2", "ssse3", "avx", "avx2",
                "bmi", "bmi2", "f16c", "fma", "lzcnt", "movbe", "xsave")


def host_runs_generic() -> bool:
    """Whether this CPU runs code compiled for :data:`GENERIC_CPU`."""
    import llvmlite.binding as ll

    try:
        features = ll.get_host_cpu_features()
    except RuntimeError:  # LLVM cannot tell on this host
        return False
    return all(features.get(name, False) for name in _V3_FEATURES)


#: the file in :data:`SHIPPED` naming the package as the build imported it
PACKAGE_FILE = "package.txt"


def fingerprint_file(python: str) -> str:
    """The file in :data:`SHIPPED` with the build's ``warmup.fingerprint()`` for Python
    ``python`` (``"3.11"``: ``fingerprint-py311.txt``)."""
    return f"fingerprint-py{python.replace('.', '')}.txt"


class _Renaming(pickle.Unpickler):
    """Unpickles a cache entry made where the package had another name (the build's staging
    package): numba stores the module of each kernel by name (its globals are rebuilt from it,
    ``numba.core.environment._rebuild_env``); here the package is ``bl_ext.<repo>.…``."""

    def __init__(self, data: bytes, old: str, new: str) -> None:
        super().__init__(io.BytesIO(data))
        self._old, self._new = old, new

    def _rename(self, module: str) -> str:
        if module == self._old or module.startswith(self._old + "."):
            return self._new + module[len(self._old):]
        return module

    def find_class(self, module: str, name: str):
        found = super().find_class(self._rename(module), name)
        if (module, name) == ("numba.core.environment", "_rebuild_env"):
            return lambda modname, *rest: found(self._rename(modname), *rest)
        return found


#: the prefixes of numba's helpers that call BLAS and LAPACK (numba's ``_helperlib``): they
#: take those routines from scipy when first called, and without scipy abort the process
_SCIPY_HELPERS = (b"numba_xx", b"numba_ez_", b"numba_raw_")


def calls_scipy(data: bytes) -> bool:
    """Whether a cached kernel (the bytes of its ``.nbc`` file) calls BLAS or LAPACK through
    numba's helpers, which need scipy at run time."""
    return any(marker in data for marker in _SCIPY_HELPERS)


def _scipy_present() -> bool:
    try:
        import scipy.linalg.cython_lapack  # noqa: F401
    except ImportError:
        return False
    return True


def _say(text: str) -> None:
    print(f"moebius_addon: {text}", file=sys.stderr, flush=True)


class _ShippedFile(caching.IndexDataCacheFile):
    """The shipped index and data files of one kernel, read only, the package renamed."""

    def __init__(self, cache_path: str, filename_base: str, source_stamp, old: str,
                 new: str) -> None:
        super().__init__(cache_path, filename_base, source_stamp)
        self._old, self._new = old, new

    def _load_data(self, name):
        with open(self._data_path(name), "rb") as f:
            data = f.read()
        if calls_scipy(data) and not _scipy_present():
            # run, such a kernel aborts the process: compiled here, it fails with an ImportError
            _say(f"the shipped kernel {name} needs scipy, which this Python does not have; "
                 "compiling it instead")
            return None
        return _Renaming(data, self._old, self._new).load()


class ShippedFunctionCache(caching.FunctionCache):
    """numba's cache of one kernel, falling back to the shipped generic-CPU entry."""

    def __init__(self, py_func, shipped: Path, old: str, new: str) -> None:
        super().__init__(py_func)
        self._shipped = _ShippedFile(str(shipped), self._impl.filename_base,
                                     self._impl.locator.get_source_stamp(), old, new)

    def _load_overload(self, sig, target_context):
        data = super()._load_overload(sig, target_context)
        if data is not None or not self._enabled:
            return data
        codegen = target_context.codegen()
        triple = codegen.magic_tuple()[0]
        key = self._index_key(sig, codegen)
        try:
            data = self._shipped.load((key[0], (triple, GENERIC_CPU, ""), key[2]))
            return None if data is None else self._impl.rebuild(target_context, data)
        except Exception as err:  # a damaged or foreign entry: compile as without the cache
            _say(f"the shipped kernel {self._py_func.__qualname__} could not be loaded "
                 f"({type(err).__name__}: {err}); compiling it instead")
            return None


#: how a module declares a cached kernel: numba's jit decorator with ``cache=True``
KERNEL_DECLARATION = re.compile(r"jit\([^)]*cache=True")


def _import_kernel_modules(package: str) -> None:
    """Import every module of ``package`` whose source declares cached kernels: a module
    imported later (an energy's record loads its sums on first use) would keep numba's own
    cache alone and compile what the package ships."""
    root = Path(sys.modules[package].__file__).parent
    for path in sorted(root.rglob("*.py")):
        if not KERNEL_DECLARATION.search(path.read_text(encoding="utf-8")):
            continue
        parts = path.relative_to(root).with_suffix("").parts
        importlib.import_module(".".join([package, *(p for p in parts if p != "__init__")]))


def use_shipped_cache(package: str) -> int:
    """Give every cached kernel of the modules of ``package`` (``moebius_addon.core``, under
    whatever name it was imported) already imported the shipped cache as a second place to look;
    returns how many. Nothing when there is no shipped cache (a source checkout, the zips of
    other platforms) or when this CPU cannot run its code."""
    if not (SHIPPED / PACKAGE_FILE).is_file() or not host_runs_generic():
        return 0
    from numba.core.dispatcher import Dispatcher

    built_as = (SHIPPED / PACKAGE_FILE).read_text().strip()
    top = package.rsplit(".", 1)[0]  # the package holding core (renamed by Blender)
    _import_kernel_modules(package)

    count = 0
    for name, module in list(sys.modules.items()):
        if module is None or not (name == package or name.startswith(package + ".")):
            continue
        for value in list(vars(module).values()):
            if (not isinstance(value, Dispatcher) or value.py_func.__module__ != name
                    or type(value._cache) is not caching.FunctionCache):
                continue
            source = Path(value.py_func.__code__.co_filename).resolve()
            try:
                shipped = SHIPPED / source.parent.relative_to(PACKAGE_ROOT)
            except ValueError:  # not a file of this package
                continue
            value._cache = ShippedFunctionCache(value.py_func, shipped, built_as, top)
            count += 1
    return count
