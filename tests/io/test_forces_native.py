"""The compiled DOP853 run from its stored machine code (dynamics/forces/native.py) against numba's
own dispatcher of the same kernel: a process that ran numba's kernel stores the code; a fresh
process then integrates without importing numba and gets the same bits (states, STM, Cr/Cd
sensitivities of a LEO day with every force); a stale or foreign copy, or arguments of other
kinds, are never used; the object's undefined symbols are those binutils' ``nm`` lists."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
pytest.importorskip("llvmlite")
if not sys.platform.startswith("linux"):
    pytest.skip("stored machine code: Linux (ELF) only", allow_module_level=True)

from test_forces_orekit import LEO  # noqa: E402
from trackproc.dynamics.forces import native  # noqa: E402

RUN = textwrap.dedent('''
    import json, sys
    import numpy as np
    LEO = json.loads(sys.argv[1])
    from trackproc.dynamics.forces import ForceModel, Spacecraft
    from trackproc.dynamics.propagator import propagate
    from trackproc.io.icgem import load_field

    EPOCH = "2020-04-05T00:00:00"
    sc = Spacecraft(mass_kg=10.0, srp_area_m2=0.1, cr=1.3, drag_area_m2=0.1, cd=2.1)
    model = ForceModel(field=load_field(degree=12, date=EPOCH), drag=True, srp=True, spacecraft=sc,
                       relativity=True, estimated=("cr", "cd"))
    t = np.linspace(0.0, 86400.0, 25)[1:]
    run = propagate(LEO[0], LEO[1], EPOCH, t, force=model, stm=True, tol=1e-12)
    out = {"numba": "numba" in sys.modules,
           "bits": [np.ascontiguousarray(a).view(np.uint64).tolist()
                    for a in (run.state(t), run.stm(t), run.parameter_partials(t))]}
    if len(sys.argv) > 2:                  # then numba in the same process, on the extensions loaded
        import numba  # noqa: F401
        again = propagate(LEO[0], LEO[1], EPOCH, t, force=model, stm=True, tol=1e-12)
        out["again"] = [np.ascontiguousarray(a).view(np.uint64).tolist()
                        for a in (again.state(t), again.stm(t), again.parameter_partials(t))]
    print(json.dumps(out))
''')


def _cache_dir(tmp_path: Path) -> Path:
    """A NUMBA_CACHE_DIR holding a copy of numba's cache of the force kernels (no compilation
    when the in-tree cache has them) and, at first, no stored machine code: numba's layout,
    ``<dir>/<package dir name>_<sha1 of its path>/``."""
    import hashlib

    root = tmp_path / "cache"
    sub = Path(native._KERNEL_SOURCE).parent
    target = root / f"{sub.name}_{hashlib.sha1(str(sub).encode()).hexdigest()}"
    target.mkdir(parents=True)
    source = Path(native.path()).parent
    for f in source.glob("compiled.*.nb[ic]") if source.exists() else ():
        shutil.copy2(f, target / f.name)
    return root


def _run(cache: Path, *more: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_") and k != "TRACKPROC_JIT"}
    env.update(NUMBA_CACHE_DIR=str(cache), TRACKPROC_JIT="1")
    out = subprocess.run([sys.executable, "-c", RUN, json.dumps(LEO), *more], env=env, capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_stored_code_gives_numbas_bits_without_numba(tmp_path):
    import numba

    from trackproc.dynamics import jit

    if not jit.light_allowed(numba.__version__):
        pytest.skip(f"numba {numba.__version__} is not one of jit.CHECKED_NUMBA: no stored code")
    cache = _cache_dir(tmp_path)
    first = _run(cache)            # numba's dispatcher; stores the code
    stored = list(cache.rglob("*.trackproc-native"))
    assert first["numba"] and len(stored) == 1
    second = _run(cache, "then-numba")                    # the stored code, then numba's dispatcher
    assert not second["numba"]
    assert second["bits"] == first["bits"] and second["again"] == first["bits"]
    # a copy whose stamp (kernel source, numba, llvmlite, Python) differs is not used
    import pickle

    record = pickle.loads(stored[0].read_bytes())
    record["stamp"] = record["stamp"][:2] + ("another source",) + record["stamp"][3:]
    stored[0].write_bytes(pickle.dumps(record))
    third = _run(cache)
    assert third["numba"] and third["bits"] == first["bits"]


def test_arguments_of_other_kinds_are_refused():
    assert native._spec((np.zeros(3), 1.0, 2, True, (np.zeros((2, 2), np.int64),))) == \
        (("<f8", 1), "float", "int", "bool", (("<i8", 2),))
    ro = np.zeros(3)
    ro.flags.writeable = False
    for bad in (ro, np.zeros((3, 3))[:, 0], np.float32(1.0), [1.0], np.zeros(3, np.float32)[::2]):
        with pytest.raises(TypeError):
            native._spec((bad,))
    assert native.load((ro,)) is None                      # numba is imported here anyway: None


def test_undefined_symbols_match_nm(tmp_path, monkeypatch):
    if shutil.which("nm") is None:
        pytest.skip("no nm")
    import numba

    from trackproc.dynamics import jit

    if not jit.light_allowed(numba.__version__):
        pytest.skip(f"numba {numba.__version__} is not one of jit.CHECKED_NUMBA: no stored code")
    stamp = native._stamp()
    record = None if stamp is None else native._read(native.path(), stamp)
    if record is None:                 # none stored yet: a short full-force arc through numba stores it
        from trackproc.dynamics.forces import ForceModel, Spacecraft
        from trackproc.dynamics.propagator import propagate
        from trackproc.io.icgem import load_field

        monkeypatch.setenv("TRACKPROC_JIT", "1")
        sc = Spacecraft(mass_kg=10.0, srp_area_m2=0.1, cr=1.3, drag_area_m2=0.1, cd=2.1)
        model = ForceModel(field=load_field(degree=4, date="2020-04-05T00:00:00"), drag=True, srp=True,
                           spacecraft=sc)
        propagate(LEO[0], LEO[1], "2020-04-05T00:00:00", np.array([600.0]), force=model)
        record = native._read(native.path(), stamp)
    assert record is not None
    obj = tmp_path / "integrate.o"
    obj.write_bytes(record["object"])
    nm = subprocess.run(["nm", "-u", str(obj)], capture_output=True, text=True, check=True).stdout
    assert sorted(native._undefined_symbols(record["object"])) == sorted(line.split()[-1] for line in nm.splitlines())
    assert native._undefined_symbols(b"not an object") is None
