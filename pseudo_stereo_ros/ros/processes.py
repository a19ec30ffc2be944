# Copyright 2026 The pseudo_stereo_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Start and stop the package's executables as child processes (benchmarks and tests).

One way everywhere: a console script of this installation, or ``python -c
CODE``, with no standard input, optionally pinned to some CPUs; stopped with a
signal that the node handles as a clean shutdown (SIGINT or SIGTERM: rclpy's
handler), killed after a timeout, so that no benchmark or test leaves a node
running.  Pipes are drained while waiting (a child blocked on a full pipe
never stops).

:func:`offset_worker` is the process a node hands heavy Python work to (the
fuser's online time-offset estimate), so that the work does not hold the
node's global interpreter lock while messages wait.
"""

from concurrent.futures import ProcessPoolExecutor
import multiprocessing
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import threading
import time
from typing import Iterable, List, Optional, Sequence, Set, Tuple

__all__ = ['console_script', 'offset_worker', 'start_python', 'start_script', 'stop_processes']


def console_script(name: str) -> str:
    """
    Return the path of a console script of this installation (beside python, or on PATH).

    :param name: the executable's name (``fuser``, ``detector``, ...)
    :return: its path
    :raises FileNotFoundError: not installed
    """
    candidate = Path(sys.executable).parent / name
    if candidate.exists():
        return str(candidate)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(f'console script {name!r} not found beside {sys.executable} '
                                'or on PATH')
    return found


def _pinned(cpus: Optional[Set[int]]):
    """Return a preexec_fn pinning the child to ``cpus`` (None: no pinning)."""
    if cpus is None:
        return None
    return lambda: os.sched_setaffinity(0, cpus)


def start_script(name: str, args: Sequence[str] = (), *, cpus: Optional[Set[int]] = None,
                 **kwargs) -> subprocess.Popen:
    """
    Start a console script of this installation.

    :param name: the executable's name (see :func:`console_script`)
    :param args: its arguments (``--ros-args ...``)
    :param cpus: pin it to these CPUs; None: no pinning
    :param kwargs: more :class:`subprocess.Popen` arguments (``stdout``, ``stderr``, ``text``)
    :return: the process
    """
    return subprocess.Popen([console_script(name), *args], stdin=subprocess.DEVNULL,
                            preexec_fn=_pinned(cpus), **kwargs)


def start_python(code: str, args: Sequence[str] = (), *, cpus: Optional[Set[int]] = None,
                 **kwargs) -> subprocess.Popen:
    """
    Start ``python -c code args...`` with this interpreter.

    :param code: the program
    :param args: its arguments (``sys.argv[1:]``)
    :param cpus: pin it to these CPUs; None: no pinning
    :param kwargs: more :class:`subprocess.Popen` arguments
    :return: the process
    """
    return subprocess.Popen([sys.executable, '-c', code, *args], stdin=subprocess.DEVNULL,
                            preexec_fn=_pinned(cpus), **kwargs)


def stop_processes(processes: Iterable[Optional[subprocess.Popen]], *,
                   signal_number: int = signal.SIGINT,
                   timeout_s: float = 10.0) -> List[Tuple[Optional[str], Optional[str]]]:
    """
    Signal every running process, then wait for each; kill one that does not stop in time.

    :param processes: the processes (None entries are skipped)
    :param signal_number: the signal (SIGINT or SIGTERM: a node shuts down cleanly)
    :param timeout_s: how long each may take to stop [s]
    :return: each process's (stdout, stderr) as read from its pipes (None when not piped;
        after a kill, what it wrote until then), in order
    """
    processes = [process for process in processes if process is not None]
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal_number)
    outputs = []
    for process in processes:
        try:
            outputs.append(process.communicate(timeout=timeout_s))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()  # reaped first: its helper processes see it gone and close the pipes
            outputs.append(process.communicate())
    return outputs


def _background_worker(node_pid: int) -> None:
    """
    Make this worker process background work: the lowest CPU priority, no Ctrl-C.

    SCHED_IDLE (Linux) runs it only when its CPUs have nothing else to run, so on the node's
    core it takes idle time only (else the lowest nice value); the parent alone handles
    Ctrl-C (a worker printed a KeyboardInterrupt traceback).  A thread ends the worker
    when the node's process is gone (killed with SIGKILL, it cannot shut the pool down).

    :param node_pid: the node's process
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        try:
            os.nice(19)
        except OSError:
            pass
    threading.Thread(target=_exit_with, args=(node_pid,), name='node watch',
                     daemon=True).start()


def _exit_with(pid: int, period_s: float = 1.0) -> None:
    """Poll process ``pid``; end this process when it is gone."""
    while True:
        time.sleep(period_s)
        if not _alive(pid):
            os._exit(0)


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, dead but not yet reaped, does not)."""
    try:
        with open(f'/proc/{pid}/stat') as stat:
            return stat.read().rpartition(')')[2].split()[0] not in ('Z', 'X')
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            pass  # it exists (as another user's process)
        return True


def offset_worker() -> ProcessPoolExecutor:
    """
    Return a one-process pool for :func:`~pseudo_stereo_ros.timesync.run_offset_job`.

    The process is forked from multiprocessing's fork server (a fresh
    interpreter that has imported :mod:`pseudo_stereo_ros.timesync`, shared
    by every pool of this process), never from the node's process itself,
    whose DDS threads a fork would copy in an unknown state.  It runs at the
    lowest CPU priority (SCHED_IDLE: on the node's core it takes idle time
    only), ignores SIGINT (the node shuts it down) and ends within a second of
    the node's process, also when that is killed.

    :return: the pool (``shutdown()`` it when done)
    """
    context = multiprocessing.get_context('forkserver')
    context.set_forkserver_preload(['pseudo_stereo_ros.timesync'])
    return ProcessPoolExecutor(max_workers=1, mp_context=context,
                               initializer=_background_worker, initargs=(os.getpid(),))
