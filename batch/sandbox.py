"""One file's work in a forked child process, with a memory and a time limit of its own.

A worker runs each file in a child forked from it (cheap: the child shares the worker's imported modules,
copy-on-write), so that a file that needs too much memory, runs too long or crashes the interpreter fails
alone, with a message that says which limit it hit, while the worker goes on to the next file. The limits
are the task's own on any cluster, an existing one included, where the engine's limits are the worker's.
The child's data memory is capped (``RLIMIT_DATA``: its heap and private writable mappings, above what
the worker had), so an allocation past the limit raises ``MemoryError`` in the child; the parent kills a
child that outlives its time. A child dies with its worker (``PR_SET_PDEATHSIG``), so a killed worker
leaves no file being written.
"""

from __future__ import annotations

import ctypes
import os
import pickle
import resource
import select
import signal
import sys
import time
from collections.abc import Callable

from cghair_format.errors import CghError

PR_SET_PDEATHSIG = 1  # linux/prctl.h


class TaskFault(CghError):
    """A file's work failed: its own error, or a limit it hit (the message says which)."""


def run_limited(fn: Callable, args: tuple, memory_mb: int, seconds: float):
    """``fn(*args)`` in a forked child with at most ``memory_mb`` MiB more data memory than this process
    and ``seconds`` of wall time; its return value (picklable), or :class:`TaskFault`."""
    if not hasattr(os, "fork"):
        raise CghError("cgh batch runs each file in a forked process, which this system lacks (use Linux or macOS)")
    read_end, write_end = os.pipe()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child; coverage does not follow forks
        os.close(read_end)
        _child(fn, args, memory_mb, write_end, parent)
    os.close(write_end)
    try:
        data = _read_until(read_end, time.monotonic() + seconds)
    finally:
        os.close(read_end)
    if data is None:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise TaskFault(f"over its time limit of {seconds:g} s (--time-per-task)")
    _, status = os.waitpid(pid, 0)
    if not data:
        why = f"signal {signal.Signals(-os.waitstatus_to_exitcode(status)).name}" if os.WIFSIGNALED(status) \
            else f"exit code {os.waitstatus_to_exitcode(status)}"
        raise TaskFault(f"its process died ({why}) without a result; nothing of it was written")
    ok, value = pickle.loads(data)
    if not ok:
        raise TaskFault(value)
    return value


def _child(fn: Callable, args: tuple, memory_mb: int, write_end: int, parent: int) -> None:  # pragma: no cover
    """Run ``fn`` and send ``(True, result)`` or ``(False, one-line error)``; never returns."""
    code = 0
    try:
        _die_with_parent(parent)
        soft = _data_size() + (memory_mb << 20)
        resource.setrlimit(resource.RLIMIT_DATA, (soft, resource.getrlimit(resource.RLIMIT_DATA)[1]))
        try:
            result = (True, fn(*args))
        except MemoryError:
            result = (False, f"over its memory limit of {memory_mb:,} MiB (--memory-per-task)")
        except CghError as exc:
            result = (False, " ".join(str(exc).split()))
        except Exception as exc:  # noqa: BLE001 - any failure of one file is that file's error
            result = (False, f"{type(exc).__name__}: {' '.join(str(exc).split())}")
        payload = pickle.dumps(result)
        view = memoryview(payload)
        while view:
            view = view[os.write(write_end, view):]
    except BaseException:  # noqa: BLE001 - nothing may escape a forked child into the worker's code
        code = 1
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _die_with_parent(parent: int) -> None:  # pragma: no cover - the child
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)


def _data_size() -> int:  # pragma: no cover - the child
    """Bytes of data memory this process has (``VmData``, what ``RLIMIT_DATA`` counts); 0 without /proc."""
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) << 10 for line in f if line.startswith("VmData:"))
    except (OSError, StopIteration):
        return 0


def _read_until(fd: int, deadline: float) -> bytes | None:
    """Everything written to ``fd`` until its writer closes it; None at ``deadline``."""
    chunks = []
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            return None
        chunk = os.read(fd, 1 << 16)
        if not chunk:
            return b"".join(chunks)
        chunks.append(chunk)
