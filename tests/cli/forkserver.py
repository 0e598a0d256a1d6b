"""A ``trackproc`` on PATH for scripts under test whose subject is the commands, not Python's start:
each call is a fork of one server process that imported trackproc and its heavy libraries once.

A command's own process costs 0.4-0.7 s of CPU, mostly imports (numpy, pandas, scipy, pyarrow and
the command's modules); the README and --help examples (tests/cli/test_examples.py) start about
sixty. Here the shim (:data:`SHIM`, ``python -IS``: no site, a few ms) hands the server its
stdin, stdout and stderr (``SCM_RIGHTS``), arguments, working directory and environment; the
server forks, the child puts them in place and runs :func:`trackproc.cli.app.main` on them, sends
the exit code back and ends. Pipes, files, exit codes and the environment are the script's own, as
with the installed script; what is not exercised is the interpreter's start and the console-script
wrapper (tests/cli/test_startup.py and the subprocess tests keep those).

The server reaps its children (so their CPU is counted in its own, and in the test run's once the
server is waited for).
"""

from __future__ import annotations

import array
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

#: the shim: ``trackproc ARGS`` -> the server, which runs the command; exits with its code
SHIM = r'''#!{python} -IS
import array, json, os, socket, sys
s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
s.connect({socket!r})
msg = json.dumps({{"argv": sys.argv[1:], "cwd": os.getcwd(), "env": dict(os.environ)}}).encode()
s.sendmsg([len(msg).to_bytes(8, "big") + msg], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", [0, 1, 2]))])
os.close(0); os.close(1)                       # the command holds them now: EOF and EPIPE as usual
code = s.recv(4)
sys.exit(int.from_bytes(code, "big") if len(code) == 4 else 70)   # 70: the server's child died
'''

#: modules imported once in the server (their import is what each fork saves); no JVM is started
PRELOAD = ("numpy", "pandas", "scipy.linalg", "scipy.optimize", "scipy.interpolate", "scipy.stats",
           "pyarrow", "pyarrow.parquet", "typer", "click")


class _NoNumba:
    """A meta path entry that refuses ``numba`` while the server preloads: a command decides whether
    to use the compiled kernels by whether numba is loaded already (jit, whitening), so the server
    must not load it (each child loads it, or not, as a fresh process would)."""

    def find_spec(self, name, path=None, target=None):
        if name == "numba" or name.startswith("numba."):
            raise ImportError("numba is not preloaded by the fork server")
        return None


#: modules never preloaded: they run work when imported (the batch pool's kernel loader), start a
#: JVM (Orekit), or run the CLI (``__main__``)
_SKIP = ("trackproc.pipeline.batch.preload_jit", "orekit", "__main__")


def _preload() -> None:
    import importlib
    import pkgutil

    import trackproc
    from trackproc.cli import root

    root._register()
    for name in PRELOAD:
        importlib.import_module(name)
    blocker = _NoNumba()
    sys.meta_path.insert(0, blocker)
    try:
        for info in pkgutil.walk_packages(trackproc.__path__, "trackproc."):
            if any(part in info.name for part in _SKIP):
                continue
            try:
                importlib.import_module(info.name)
            except Exception:                            # noqa: BLE001 - e.g. it needs numba: the command imports it
                pass
    finally:
        sys.meta_path.remove(blocker)
    from trackproc.dynamics import jit

    jit._numba_importable.cache_clear()                  # nothing may remember the refusal
    assert "numba" not in sys.modules, "the fork server loaded numba"
    from trackproc.dynamics import taylor
    from trackproc.methods import whitening

    assert not taylor._JIT_MODULE and not whitening._RICCATI, "a kernel lookup ran while preloading"


def _recv(conn: socket.socket):
    fds = array.array("i")
    data, ancdata, _, _ = conn.recvmsg(1 << 20, socket.CMSG_SPACE(3 * fds.itemsize))
    for level, kind, cdata in ancdata:
        if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
            fds.frombytes(cdata[:len(cdata) - len(cdata) % fds.itemsize])
    size = int.from_bytes(data[:8], "big")
    data = data[8:]
    while len(data) < size:
        chunk = conn.recv(size - len(data))
        if not chunk:
            raise ConnectionError("shim closed the connection")
        data += chunk
    return json.loads(data), list(fds)


def _child(conn: socket.socket, request: dict, fds: list[int]) -> None:
    """In the forked child: become the shim's process (fds, cwd, environment) and run the command."""
    import logging
    import signal

    code = 70
    try:
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        for target, fd in zip((0, 1, 2), fds):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        sys.argv = ["trackproc", *request["argv"]]
        from trackproc.cli.app import main

        code = main(list(request["argv"]))
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:                                 # noqa: BLE001 - report, then the code says it failed
        import traceback

        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        logging.shutdown()
        try:
            conn.sendall(int(code).to_bytes(4, "big"))
        except OSError:
            pass
        os._exit(code)


def serve(path: str) -> None:
    _preload()
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(path)
    server.listen(64)
    server.settimeout(0.2)
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    while True:
        try:
            conn, _ = server.accept()
        except socket.timeout:
            conn = None
        while True:                                       # reap: the children's CPU joins the server's
            try:
                pid, _, usage = os.wait4(-1, os.WNOHANG)
            except ChildProcessError:
                break
            if pid == 0:
                break
            _account(pid, usage)
        if conn is None:
            if os.getppid() == 1:                         # the test run is gone
                return
            continue
        conn.settimeout(None)
        request, fds = _recv(conn)
        if request.get("stop"):
            conn.close()
            break
        pid = os.fork()
        if pid == 0:
            server.close()
            _child(conn, request, fds)
        _COMMANDS[pid] = request["argv"]
        for fd in fds:
            os.close(fd)
        conn.close()
    while True:                                           # wait for the last children, then end
        try:
            pid, _, usage = os.wait4(-1, 0)
        except ChildProcessError:
            return
        _account(pid, usage)


#: pid -> argv of the commands running; with TRACKPROC_FORKSERVER_LOG set, each one's CPU seconds and
#: argv are appended there when it is reaped (which example costs what: the server's CPU reaches the
#: test run only when it ends)
_COMMANDS: dict = {}


def _account(pid: int, usage) -> None:
    argv = _COMMANDS.pop(pid, None)
    path = os.environ.get("TRACKPROC_FORKSERVER_LOG")
    if path and argv is not None:
        with open(path, "a") as log:
            log.write(json.dumps({"cpu": round(usage.ru_utime + usage.ru_stime, 3), "argv": argv}) + "\n")


class ForkServer:
    """``with ForkServer(directory) as bin_dir:`` a ``trackproc`` in ``bin_dir`` served by a
    forking server that started (and imported trackproc) once."""

    def __init__(self, directory: Path, env: dict):
        self.directory, self.env = Path(directory), env

    def __enter__(self) -> Path:
        sock = self.directory / "trackproc.sock"
        if len(str(sock)) > 100:                          # AF_UNIX paths hold ~107 bytes
            import tempfile

            sock = Path(tempfile.mkdtemp(prefix="tpfs-", dir="/tmp")) / "s"
        bin_dir = self.directory / "bin"
        bin_dir.mkdir(parents=True, exist_ok=True)
        shim = bin_dir / "trackproc"
        shim.write_text(SHIM.format(python=sys.executable, socket=str(sock)))
        shim.chmod(0o755)
        self.proc = subprocess.Popen([sys.executable, __file__, str(sock)], env=self.env, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, text=True)
        ready = self.proc.stdout.readline()
        assert ready == "ready\n", f"fork server did not start: {ready!r}"
        self.sock = sock
        return bin_dir

    def __exit__(self, *exc) -> None:
        try:
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(str(self.sock))
            msg = json.dumps({"stop": True}).encode()
            s.sendall(len(msg).to_bytes(8, "big") + msg)
            s.close()
            self.proc.wait(timeout=120)
        except Exception:                                 # noqa: BLE001 - never leave it running
            self.proc.kill()
            self.proc.wait()


if __name__ == "__main__":
    serve(sys.argv[1])
