"""The compiled DOP853 of the full force model (:func:`trackproc.dynamics.forces.compiled.integrate`)
run from its stored machine code without importing numba.

Why: a full-force LEO day integrates in ~0.05 s of CPU, but importing numba costs ~0.17 s and
loading the kernel from numba's cache ~0.07 s more (unpickling, importing the modules its
environments name, parsing its bitcode): over half the process. The machine code itself needs
only LLVM's loader (``llvmlite.binding``, ~0.04 s), numba's three small C extensions (the runtime's
allocator, the helper functions, the function wrapper) and the Python C API.

How: after a process ran the kernel through numba, :func:`export` copies the object code numba
cached for that signature, with the names of its wrapper and environments and the signature's
argument kinds, into a file beside numba's cache. :func:`load` (in a process where numba is not
imported) loads numba's C extensions from their files, registers the symbols numba registers
(``numba.core.base._load_global_helpers``, ``numba.core.runtime.nrt``), links the object with
LLVM's MCJIT, points the environments at fresh ones and wraps the entry point with
``_dynfunc.make_function``, as ``numba.core.compiler.CompileResult._rebuild`` and
``CPUContext.get_executable`` do: the same machine code, hence the same bits.

Used only with a numba release it was checked against
(:data:`trackproc.dynamics.jit.CHECKED_NUMBA`, not with ``TRACKPROC_JIT_LIGHT=0``) and when
everything it depends on is the same as when it was written (the kernel's source, Python, numba's
and llvmlite's binaries, the CPU and LLVM's view of its features, no ``NUMBA_*`` setting), every undefined symbol of the object resolves, and the arguments have exactly the
recorded types (numba's wrapper trusts them: the dispatcher's type check is skipped); otherwise
the caller runs numba's dispatcher, which is always correct. Linux (ELF) only.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import struct
import sys

import numpy as np

__all__ = ["export", "load", "path", "stored"]

_FORMAT = 1
_KERNEL_SOURCE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "compiled.py")
#: numba's extension modules the machine code calls into (module name, file stem under numba/).
_EXTENSIONS = (("numba._helperlib", "_helperlib"), ("numba._dynfunc", "_dynfunc"),
               ("numba.core.runtime._nrt_python", os.path.join("core", "runtime", "_nrt_python")))
_LOADED: dict = {}


def _package_dir(name: str) -> str | None:
    import importlib.util

    spec = importlib.util.find_spec(name)           # a top-level package: located, not imported
    if spec is None or not spec.submodule_search_locations:
        return None
    return list(spec.submodule_search_locations)[0]


def _extension_files() -> list[str] | None:
    import importlib.machinery

    numba_dir, llvmlite_dir = _package_dir("numba"), _package_dir("llvmlite")
    if numba_dir is None or llvmlite_dir is None:
        return None
    files = []
    for _, stem in _EXTENSIONS:
        found = [os.path.join(numba_dir, stem + s) for s in importlib.machinery.EXTENSION_SUFFIXES
                 if os.path.exists(os.path.join(numba_dir, stem + s))]
        if not found:
            return None
        files.append(found[0])
    binding = os.path.join(llvmlite_dir, "binding")
    files += sorted(os.path.join(binding, f) for f in os.listdir(binding) if "llvmlite" in f and f.endswith(".so"))
    return files


def _stamp() -> tuple | None:
    """What the stored code depends on, short of the CPU: format, Python, the kernel's source and
    numba's and llvmlite's binaries (size and modification time)."""
    files = _extension_files()
    if files is None:
        return None
    with open(_KERNEL_SOURCE, "rb") as f:
        source = hashlib.sha256(f.read()).hexdigest()
    binaries = tuple((f, os.stat(f).st_size, os.stat(f).st_mtime_ns) for f in files)
    return _FORMAT, sys.implementation.cache_tag, source, binaries


_NAME = f"compiled.integrate.{sys.implementation.cache_tag}.trackproc-native"


def _candidates() -> list[str]:
    """Where numba keeps the cache of compiled.py, hence where the stored code is looked for:
    ``NUMBA_CACHE_DIR`` when set, else the package's ``__pycache__`` or, when that was not
    writable, the user's cache (numba's _CacheLocator classes, same subdirectory names)."""
    here = os.path.dirname(_KERNEL_SOURCE)
    sub = f"{os.path.basename(here)}_{hashlib.sha1(here.encode()).hexdigest()}"
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        return [os.path.join(root, sub, _NAME)]
    user = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return [os.path.join(here, "__pycache__", _NAME), os.path.join(user, "numba", sub, _NAME)]


def path() -> str:
    """The stored code's file: the first of the places numba may cache compiled.py that holds one,
    else the first place."""
    candidates = _candidates()
    return next((c for c in candidates if os.path.exists(c)), candidates[0])


def _spec(value):
    """The kind of an argument as numba types it (C-contiguous arrays by dtype and rank)."""
    if type(value) in (bool, int, float):
        return type(value).__name__
    if type(value) is tuple:
        return tuple(_spec(v) for v in value)
    if type(value) is np.ndarray and value.flags.c_contiguous and value.flags.aligned and value.flags.writeable:
        return value.dtype.str, value.ndim
    raise TypeError(f"no stored-code argument kind for {type(value).__name__}")


def _undefined_symbols(obj: bytes) -> list[str] | None:
    """The undefined symbols of an ELF64 little-endian object (its symbol table), None otherwise."""
    if obj[:4] != b"\x7fELF" or obj[4] != 2 or obj[5] != 1:
        return None
    shoff, = struct.unpack_from("<Q", obj, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", obj, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", obj, shoff + i * shentsize) for i in range(shnum)]
    names = []
    for _, kind, _, _, off, size, link, _, _, entsize in sections:
        if kind != 2:                                     # SHT_SYMTAB
            continue
        stroff = sections[link][4]
        for k in range(size // entsize):
            st_name, _, _, st_shndx = struct.unpack_from("<IBBH", obj, off + k * entsize)
            if st_shndx == 0 and st_name:                 # SHN_UNDEF, named
                end = obj.index(b"\0", stroff + st_name)
                names.append(obj[stroff + st_name:end].decode())
    return names


def export(kernel, args) -> bool:
    """Store the machine code numba cached for ``kernel`` called with ``args`` (numba loaded, the
    call made), unless an up-to-date copy is there; True when written. Once per process (a
    batch worker calls the kernel per task). Any failure: nothing written (numba's path stays
    the one used)."""
    if _LOADED.setdefault("exported", False):
        return False
    _LOADED["exported"] = True
    try:
        import numba

        from trackproc.dynamics import jit

        if not jit.light_allowed(numba.__version__):
            return False
        target = os.path.join(kernel._cache._cache_path, _NAME)   # where numba cached it
        stamp = _stamp()
        if stamp is None or _read(target, stamp) is not None:
            return False
        spec = _spec(tuple(args))
        sig = tuple(kernel.typeof_pyval(a) for a in args)
        key = kernel._cache._index_key(sig, kernel.targetctx.codegen())
        data = kernel._cache._cache_file.load(key)
        if data is None:
            return False
        libdata, fndesc, env, _, objectmode, _, _, reload_init, referenced = data
        _, kind, payload = libdata
        if kind != "object" or objectmode or reload_init:
            return False
        obj = payload[0]
        undefined = _undefined_symbols(obj)
        consts = [list(env.consts)] + [list(e.consts) for e in referenced]
        if undefined is None or any(type(c).__module__.split(".")[0] not in ("numpy", "builtins")
                                    for group in consts for c in group):
            return False
        record = {"stamp": stamp, "magic": key[1], "spec": spec, "object": obj, "undefined": undefined,
                  "wrapper": fndesc.llvm_cpython_wrapper_name, "env": (fndesc.env_name, consts[0]),
                  "module": fndesc.modname, "name": fndesc.qualname.split(".")[-1],
                  "environments": [(e.env_name, e.globals.get("__name__"), c) for e, c in zip(referenced, consts[1:])]}
        os.makedirs(os.path.dirname(target), exist_ok=True)
        tmp = f"{target}.{os.getpid()}.tmp"
        with open(tmp, "wb") as f:
            pickle.dump(record, f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, target)
        return True
    except Exception:                                     # noqa: BLE001 - an optional saving, never a failure
        return False


def _read(target: str, stamp) -> dict | None:
    try:
        with open(target, "rb") as f:
            record = pickle.load(f)
    except Exception:                                     # noqa: BLE001 - missing, partial or foreign: not used
        return None
    return record if isinstance(record, dict) and record.get("stamp") == stamp else None


def _numba_version() -> str | None:
    """The installed numba's version from its ``.dist-info`` directory beside the package (numba
    itself not imported), None when there is not exactly one."""
    numba_dir = _package_dir("numba")
    if numba_dir is None:
        return None
    found = [name[len("numba-"):-len(".dist-info")] for name in os.listdir(os.path.dirname(numba_dir))
             if name.startswith("numba-") and name.endswith(".dist-info")]
    return found[0] if len(found) == 1 else None


def _usable() -> bool:
    from trackproc.dynamics import jit

    if "usable" not in _LOADED:                           # the version and the settings: once a process
        _LOADED["usable"] = jit.light_allowed(_numba_version()) and not any(
            k.startswith("NUMBA_") and k != "NUMBA_CACHE_DIR" for k in os.environ)
    return "numba" not in sys.modules and _LOADED["usable"]


def _record() -> dict | None:
    if "record" not in _LOADED:
        stamp = _stamp()
        found = (_read(c, stamp) for c in (_candidates() if stamp is not None else ()))
        _LOADED["record"] = next((r for r in found if r is not None), None)
    return _LOADED["record"]


def stored() -> bool:
    """True when :func:`load` may find the kernel: numba not imported, no ``NUMBA_*`` setting but
    ``NUMBA_CACHE_DIR``, and an up-to-date stored copy (the CPU and the arguments are checked at
    :func:`load`)."""
    try:
        return _usable() and _record() is not None
    except Exception:                                     # noqa: BLE001 - then numba's path
        return False


def load(args):
    """The stored kernel as a callable of ``args``, or None (then use numba's dispatcher): numba not
    imported in this process, no ``NUMBA_*`` setting but ``NUMBA_CACHE_DIR``, an up-to-date
    stored copy for this CPU whose symbols all resolve, and ``args`` of the recorded kinds."""
    if not _usable():
        return None
    try:
        spec = _spec(tuple(args))
    except TypeError:
        return None
    if spec in _LOADED:
        return _LOADED[spec]
    try:
        record = _record()
        if record is None or record["spec"] != spec:
            return None
        fn = _link(record)
    except Exception:                                     # noqa: BLE001 - numba's dispatcher then
        return None
    _LOADED[spec] = fn
    return fn


_UNPICKLED: dict = {}


def _unpickler():
    """``numba_unpickle`` (numba/_helperlib.c) without numba: the wrapper unpickles the class of
    the arrays it returns (``numpy.ndarray``); numba's version imports ``numba.core.serialize``,
    hence all of numba. The same memo: one object per pickled constant (its address and hash)."""
    import ctypes

    if "callback" not in _UNPICKLED:
        @ctypes.CFUNCTYPE(ctypes.py_object, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p)
        def unpickle(data, size, hashed):
            key = (data, ctypes.string_at(hashed, 20))
            if key not in _UNPICKLED:
                _UNPICKLED[key] = pickle.loads(ctypes.string_at(data, size))
            return _UNPICKLED[key]

        _UNPICKLED["callback"] = unpickle
    return _UNPICKLED["callback"]


def _link(record):
    import builtins
    import ctypes
    import importlib.machinery
    import importlib.util
    import types

    import llvmlite.binding as ll

    ll.initialize_native_target()
    ll.initialize_native_asmprinter()
    magic = (ll.get_process_triple(), ll.get_host_cpu_name(), ll.get_host_cpu_features().flatten())
    if tuple(record["magic"]) != magic:
        return None
    files = _extension_files()
    modules = {}
    for (name, _), file in zip(_EXTENSIONS, files):
        module = sys.modules.get(name)
        if module is None:                                # numba, imported later, finds and reuses it
            loader = importlib.machinery.ExtensionFileLoader(name, file)
            module = importlib.util.module_from_spec(importlib.util.spec_from_loader(name, loader, origin=file))
            loader.exec_module(module)
            sys.modules[name] = module
        modules[name] = module
    helperlib, dynfunc, nrt = (modules[name] for name, _ in _EXTENSIONS)
    nrt.memsys_use_cpython_allocator()                    # numba.core.runtime.nrt, at its import
    # numba.core.base._load_global_helpers and numba.core.runtime.nrt._Runtime.initialize
    ll.add_symbol("_Py_NoneStruct", id(None))
    for module in (helperlib, dynfunc):
        for name, address in module.c_helpers.items():
            ll.add_symbol("numba_" + name, address)
    for obj in builtins.__dict__.values():
        if isinstance(obj, type) and issubclass(obj, BaseException):
            ll.add_symbol(f"PyExc_{obj.__name__}", id(obj))
    for name, address in nrt.c_helpers.items():
        ll.add_symbol(name if name.startswith("_") else "NRT_" + name, address)
    ll.add_symbol("numba_unpickle", ctypes.cast(_unpickler(), ctypes.c_void_p).value)
    machine = ll.Target.from_triple(magic[0]).create_target_machine(
        cpu=magic[1], features=magic[2], opt=3, reloc="default", codemodel="jitdefault", jit=True)
    engine = ll.create_mcjit_compiler(ll.parse_assembly(""), machine)
    if not all(ll.address_of_symbol(name) for name in record["undefined"]):
        return None                                       # LLVM would abort the process on an unresolved one
    engine.add_object_file(ll.ObjectFileRef.from_data(record["object"]))
    engine.finalize_object()
    keep = [engine, machine]

    def environment(env_name, module_name, consts):
        env = dynfunc.Environment({"__name__": module_name})
        env.consts[:] = consts
        address = engine.get_global_value_address(env_name)
        if not address:
            raise LookupError(env_name)
        ctypes.c_void_p.from_address(address).value = id(env)   # numba.core.codegen.JITCPUCodegen.set_env
        keep.append(env)
        return env

    for env_name, module_name, consts in record["environments"]:
        environment(env_name, module_name, consts)
    env = environment(record["env"][0], record["module"], record["env"][1])
    address = engine.get_function_address(record["wrapper"])
    if not address:
        return None
    return dynfunc.make_function(types.ModuleType(record["module"]), record["name"], "stored machine code of "
                                 + record["name"], address, env, tuple(keep))
