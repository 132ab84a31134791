"""A fork server for the SITL tests: the FC's and the bridge's processes forked from one pre-imported, pre-warmed
Python process instead of each started as a new interpreter: a pair costs ~0.6 s of CPU instead of ~2.3 s (the
imports, numba's first dispatch and its cache loads, done once in the server; tests/sitl/pair_cpu.py), over a hundred
starts in the SITL lane.

A forked child is a process of its own, as `python -m MODULE ARGS` would be: it gets the test's argv, working
directory, environment and stdin/stdout/stderr, runs the module's code in a fresh __main__ (as -m does), binds its own
sockets and exits with the module's exit code after Python's own shutdown steps (non-daemon threads joined, atexit
handlers, streams flushed). The test holds it through `ForkedProcess`, the part of subprocess.Popen the tests use.

The server forks only while it is single-threaded (checked before every fork: a fork with another thread alive
could copy a held lock into the child); it starts none itself, and the warm-up (imports, a controller's and a plant's
first steps) starts none: OpenBLAS is held to one thread (OPENBLAS_NUM_THREADS, tests/conftest.py) and no kernel is
parallel. Otherwise, or on any failure of the server, `start` returns None and the caller starts an interpreter.

Protocol (Unix SOCK_SEQPACKET, one message a datagram): a start is JSON {module, argv, cwd, env} on the control
socket with four descriptors: the child's stdin, stdout, stderr and its status socket. The server answers on the
status socket {"pid": n} (or {"error": text}) and, when the child has ended, {"status": its wait status, "cpu_s":
its CPU time}. The
server ends when the control socket closes (the test process is gone), killing any child still running.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path
from typing import Any

# The modules the server imports and warms: what tests start through it. Anything else is an interpreter of its own.
MODULES = ("navig8_fc.shell.fc_process", "sim_bridge.bridge")
# The environment a module reads at import (numba, BLAS, pymavlink's dialect, Python's own): a child asked for with
# values the server did not import under is started as an interpreter instead.
_IMPORT_ENV_PREFIXES = ("NUMBA_", "OPENBLAS_", "OMP_", "MKL_", "MAVLINK", "PYTHON", "NAVIG8_")
_MAX_MSG = 1 << 20
_READY_TIMEOUT_S = 120.0  # the server's imports and warm-up on a loaded machine (a fresh numba cache compiles)
_REPLY_TIMEOUT_S = 30.0  # a fork's pid


# ---- the server -------------------------------------------------------------------------------------------------

def _threads() -> int:
    return len(os.listdir("/proc/self/task"))


def _warm() -> None:
    """Import the two entry points and run what every start of them runs once, so a child inherits it loaded:
    the dialect, the parameter registry, the vehicle model, a controller's ticks (numba's dispatch and its cached
    kernels; warm_up_kernels), and a plant's steps, sensors and truth (the bridge's kernels)."""
    import importlib

    for m in MODULES:
        importlib.import_module(m)
    import numpy as np

    from navig8_fc.core import vehicle as vm
    from navig8_fc.core.controller import warm_up_kernels
    from navig8_fc.flight import FlightStack, load_flight_script
    from navig8_fc.mavlink import dialect as dialect_mod
    from navig8_fc.params.registry import ParamRegistry
    from navig8_fc.shell.fc_options import build_arg_parser, options_from_args
    from sim_bridge.plant import Plant
    from sim_bridge.world import load_world

    dialect_mod.load()
    opts = options_from_args(build_arg_parser().parse_args([]))
    vehicle = vm.VehicleConfig.load(opts.vehicle_path)
    registry = ParamRegistry.from_defaults()
    vm.UamModel(vehicle)
    stack = FlightStack(vehicle, registry, load_flight_script("ground"))
    stack.reconfigure()
    warm_up_kernels(vehicle, stack.core.config)
    w = load_world("ground", {})
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(1))
    cmd = plant.trim_command()
    for _ in range(3):
        plant.step_us(cmd, 4 * plant.physics_step_us)
        plant.sense_wire()
        plant.truth_floats()


def _exit_code(code: object) -> int:
    """sys.exit's argument as the interpreter turns it into an exit status (anything else printed, status 1)."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code & 0xFF
    print(code, file=sys.stderr)
    return 1


def _child(req: dict[str, Any], fds: list[int], close: list[int]) -> None:
    """In the forked child: become `python -m MODULE ARGV` and exit with its status. Never returns."""
    code = 1
    try:
        signal.set_wakeup_fd(-1)
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        for fd in close:
            os.close(fd)
        stdin, stdout, stderr, status = fds
        os.close(status)
        for fd, to in ((stdin, 0), (stdout, 1), (stderr, 2)):
            os.dup2(fd, to)
        for fd in {stdin, stdout, stderr} - {0, 1, 2}:
            os.close(fd)
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        sys.path[0] = os.getcwd()  # `python -m` puts the working directory first
        code = 0
        try:
            _run_as_main(req["module"], req["argv"])
        except SystemExit as e:
            code = _exit_code(e.code)
        except KeyboardInterrupt:  # as the interpreter does: the traceback, then death by SIGINT
            traceback.print_exc()
            _finish()
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGINT)
        except BaseException:  # noqa: BLE001 - printed as the interpreter prints it, status 1
            traceback.print_exc()
            code = 1
        _finish()
    finally:
        os._exit(code)


def _run_as_main(module: str, argv: list[str]) -> None:
    """The module's code run as __main__, as `python -m` runs it (runpy's own entry would warn that the module is
    imported already: here it is, in the server, as in any process that imports it again after -m)."""
    import builtins
    import importlib.util
    import types

    spec = importlib.util.find_spec(module)
    assert spec is not None and spec.loader is not None and spec.origin is not None
    code = spec.loader.get_code(module)  # type: ignore[attr-defined]
    main = types.ModuleType("__main__")
    main.__dict__.update(__file__=spec.origin, __cached__=spec.cached, __loader__=spec.loader, __spec__=spec,
                         __package__=spec.parent, __builtins__=builtins)
    sys.modules["__main__"] = main
    sys.argv = [spec.origin, *argv]
    exec(code, main.__dict__)


def _finish() -> None:
    """Python's shutdown as a program sees it: non-daemon threads joined, atexit handlers run, streams flushed."""
    import atexit

    try:
        threading._shutdown()  # type: ignore[attr-defined]
    except Exception:  # noqa: BLE001
        traceback.print_exc()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a closed pipe: nothing more to say
            pass


def _send(sock: socket.socket, obj: dict[str, Any]) -> None:
    try:
        sock.send(json.dumps(obj).encode())
    except OSError:  # the test process let go of it
        pass


def serve(ctl: socket.socket) -> None:
    rd, wr = os.pipe()
    os.set_blocking(rd, False)
    os.set_blocking(wr, False)
    signal.set_wakeup_fd(wr)
    signal.signal(signal.SIGCHLD, lambda *_: None)  # wakes the select through the wakeup fd
    children: dict[int, socket.socket] = {}
    import_env = {k: v for k, v in os.environ.items() if k.startswith(_IMPORT_ENV_PREFIXES)}
    try:
        while True:
            ready, _, _ = select.select([ctl, rd], [], [], 5.0)
            if rd in ready:
                try:
                    while os.read(rd, 512):
                        pass
                except BlockingIOError:
                    pass
            _reap(children)
            if ctl not in ready:
                continue
            try:
                msg, fds, _flags, _addr = socket.recv_fds(ctl, _MAX_MSG, 4)
            except ConnectionError:
                return  # the test process is gone
            if not msg:
                return  # the test process is gone
            if len(fds) != 4:
                for fd in fds:
                    os.close(fd)
                continue
            status = socket.socket(fileno=fds[3])
            req = json.loads(msg)
            env = {k: v for k, v in req["env"].items() if k.startswith(_IMPORT_ENV_PREFIXES)}
            why = None
            if req["module"] not in MODULES:
                why = f"not a module the server imported: {req['module']}"
            elif env != import_env:
                why = "an environment the server did not import under"
            elif _threads() != 1:
                why = f"the server has {_threads()} threads"
            if why is not None:
                _send(status, {"error": why})
                status.close()
                for fd in fds[:3]:
                    os.close(fd)
                continue
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                _child(req, fds, [ctl.fileno(), rd, wr, *(s.fileno() for s in children.values())])
            for fd in fds[:3]:
                os.close(fd)
            children[pid] = status
            _send(status, {"pid": pid})
    finally:
        for pid in children:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + 10.0
        while children and time.monotonic() < deadline:
            _reap(children)
            time.sleep(0.01)


def _reap(children: dict[int, socket.socket]) -> None:
    while children:
        try:
            pid, st, ru = os.wait4(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        sock = children.pop(pid, None)
        if sock is not None:
            _send(sock, {"status": st, "cpu_s": ru.ru_utime + ru.ru_stime})
            sock.close()


def server_main() -> None:
    ctl = socket.socket(fileno=int(sys.argv[1]))
    _warm()
    import gc

    gc.collect()
    gc.freeze()  # the warmed objects stay untouched by the children's collections (their pages stay shared)
    if _threads() != 1:
        ctl.send(json.dumps({"error": f"{_threads()} threads after the warm-up"}).encode())
        return
    ctl.send(json.dumps({"ready": os.getpid()}).encode())
    serve(ctl)


# ---- the test process's side ------------------------------------------------------------------------------------

class ForkedProcess:
    """A process the fork server started, as the SITL tests use a subprocess.Popen: pid, args, stdout (bytes),
    poll, wait, send_signal, terminate, kill, returncode (negative: the signal that ended it)."""

    def __init__(self, args: list[str], pid: int, status: socket.socket, stdout: Any, stderr: Any = None,
                 text: bool = False) -> None:
        self.args = args
        self.pid = pid
        self.stdout = stdout
        self.stdin = None
        self.stderr = stderr
        self.text_mode = text
        self.returncode: int | None = None
        self.cpu_s: float | None = None  # its CPU time (user + system; its own children's included), once ended
        self._status = status

    def _collect(self, timeout_s: float | None) -> None:
        if self.returncode is not None:
            return
        ready, _, _ = select.select([self._status], [], [], timeout_s)
        if not ready:
            return
        msg = self._status.recv(_MAX_MSG)
        self._status.close()
        if not msg:  # the server died before the child: the child was killed with it
            self.returncode = -signal.SIGKILL
            return
        reply = json.loads(msg)
        self.returncode = os.waitstatus_to_exitcode(reply["status"])
        self.cpu_s = reply["cpu_s"]

    def poll(self) -> int | None:
        self._collect(0.0)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        self._collect(timeout)
        if self.returncode is None:
            raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        return self.returncode

    def communicate(self, timeout: float | None = None) -> tuple[Any, Any]:
        """What is left on stdout and stderr (None for one not piped), both read to their ends, then the exit awaited;
        subprocess.TimeoutExpired when that has not all happened within timeout."""
        deadline = None if timeout is None else time.monotonic() + timeout
        files = [f for f in (self.stdout, self.stderr) if f is not None]
        open_fds = {f.fileno() for f in files if not f.closed}
        got: dict[int, list[bytes]] = {f.fileno(): [] for f in files}
        while open_fds:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
            ready, _, _ = select.select(list(open_fds), [], [], left)
            for fd in ready:
                data = os.read(fd, 65536)
                if data:
                    got[fd].append(data)
                else:
                    open_fds.discard(fd)
        results: list[Any] = []
        for f in (self.stdout, self.stderr):
            if f is None:
                results.append(None)
                continue
            data = b"".join(got[f.fileno()])
            f.close()
            # text as subprocess gives it: decoded, universal newlines
            results.append(data.decode().replace("\r\n", "\n").replace("\r", "\n") if self.text_mode else data)
        self.wait(None if deadline is None else max(0.0, deadline - time.monotonic()))
        return results[0], results[1]

    def send_signal(self, sig: int) -> None:
        self.poll()
        if self.returncode is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:
                pass

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class ForkServer:
    def __init__(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), str(theirs.fileno())],
                                      pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                      stdout=subprocess.DEVNULL, cwd=Path(__file__).resolve().parent)
        theirs.close()
        self._ctl = ours
        self._lock = threading.Lock()
        self._ready: bool | None = None  # None: not yet heard from (it imports and warms meanwhile)

    def _wait_ready(self) -> bool:
        if self._ready is None:
            ready, _, _ = select.select([self._ctl], [], [], _READY_TIMEOUT_S)
            reply = json.loads(self._ctl.recv(_MAX_MSG) or b"{}") if ready else {"error": "not ready in time"}
            self._ready = "ready" in reply
            if not self._ready:
                print(f"fork server: {reply.get('error', 'exited')}; starting interpreters", file=sys.stderr)
        return self._ready

    def start(self, module: str, argv: list[str], cwd: Path | str, stdout: int = subprocess.PIPE,
              stderr: int = subprocess.STDOUT, text: bool = False) -> ForkedProcess | None:
        """`python -m module *argv` in cwd, forked, stdin /dev/null; stdout PIPE or DEVNULL, stderr PIPE, STDOUT or
        DEVNULL, the pipes bytes or (text) str as subprocess.Popen gives them; None when the server will not fork
        it (the caller starts an interpreter)."""
        with self._lock:
            if not self._wait_ready():
                return None
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        mine: list[int] = []  # our read ends
        theirs_fds: list[int] = []  # what the child gets (closed here once sent)
        try:
            devnull = os.open(os.devnull, os.O_RDWR)
            theirs_fds.append(devnull)
            ends = {}
            for name, how in (("out", stdout), ("err", stderr)):
                if how == subprocess.PIPE:
                    rd, wr = os.pipe()
                    mine.append(rd)
                    ends[name] = (rd, wr)
                    theirs_fds.append(wr)
                elif how == subprocess.STDOUT and name == "err" and "out" in ends:
                    ends[name] = (None, ends["out"][1])
                else:
                    ends[name] = (None, devnull)
            req = {"module": module, "argv": list(argv), "cwd": str(cwd), "env": dict(os.environ)}
            with self._lock:
                socket.send_fds(self._ctl, [json.dumps(req).encode()],
                                [devnull, ends["out"][1], ends["err"][1], theirs.fileno()])
            for fd in theirs_fds:
                os.close(fd)
            theirs_fds.clear()
            theirs.close()
            ready, _, _ = select.select([ours], [], [], _REPLY_TIMEOUT_S)
            reply = json.loads(ours.recv(_MAX_MSG) or b"{}") if ready else {}
            if "pid" not in reply:
                raise OSError(reply.get("error", "no pid from the fork server"))
            mode = "r" if text else "rb"
            files = [open(ends[n][0], mode) if ends[n][0] is not None else None  # noqa: SIM115 - the caller's
                     for n in ("out", "err")]
            mine.clear()
            return ForkedProcess([sys.executable, "-m", module, *argv], reply["pid"], ours, files[0], files[1], text)
        except OSError:
            ours.close()
            for fd in mine + theirs_fds:
                os.close(fd)
            return None
        finally:
            theirs.close()

    def close(self) -> None:
        self._ctl.close()
        try:
            self._proc.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait(timeout=10.0)


if __name__ == "__main__":
    server_main()
