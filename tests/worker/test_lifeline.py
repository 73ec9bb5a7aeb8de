"""The shutdown guard ends a process whose main thread is stuck and deaf to signals (issue 30).

Each test runs a small Python process that installs :class:`texsynth.worker.lifeline.ShutdownGuard`, ignores
SIGTERM in Python (as Celery's handlers do during a shutdown) and blocks its main thread on a lock
forever (as Celery's cold shutdown did, in a futex); the guard must end it, and its child, anyway.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tests.paths import REPO
from texsynth.worker.lifeline import ShutdownGuard, children

STUCK = textwrap.dedent(
    """
    import os, signal, subprocess, sys, threading
    from texsynth.worker.lifeline import ShutdownGuard
    words = sys.argv[2]
    parent_fd = int(sys.argv[3]) if len(sys.argv) > 3 else None
    def last_words():
        open(words, "w").write("said")
    ShutdownGuard(float(sys.argv[1]), last_words, parent_fd).install()
    signal.signal(signal.SIGTERM, lambda *_: None)  # a handler that does nothing, like Celery's 2nd
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    print(child.pid, flush=True)
    lock = threading.Lock()
    lock.acquire()
    lock.acquire()  # stuck for good
    """
)


def _stuck(tmp_path: Path, grace: float, pass_fd: int | None = None) -> tuple[subprocess.Popen, int]:
    args = [sys.executable, "-c", STUCK, str(grace), str(tmp_path / "words")]
    if pass_fd is not None:
        args.append(str(pass_fd))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        args,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        pass_fds=() if pass_fd is None else (pass_fd,),
    )
    child = int(proc.stdout.readline())
    return proc, child


def _gone(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def _finish(proc: subprocess.Popen, child: int, timeout: float) -> str:
    try:
        _, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    deadline = time.monotonic() + 5
    while not _gone(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _gone(child), "the guarded process's child outlived it"
    return err


def test_a_second_sigterm_ends_a_stuck_process(tmp_path):
    proc, child = _stuck(tmp_path, grace=120)
    proc.send_signal(signal.SIGTERM)
    time.sleep(0.5)
    assert proc.poll() is None  # the first signal starts the grace, no more
    proc.send_signal(signal.SIGTERM)
    err = _finish(proc, child, timeout=30)
    assert proc.returncode == 1
    assert "a second stop signal (SIGTERM)" in err
    assert (tmp_path / "words").read_text() == "said"


def test_the_end_of_the_grace_ends_a_stuck_process(tmp_path):
    proc, child = _stuck(tmp_path, grace=0.5)
    proc.send_signal(signal.SIGTERM)
    err = _finish(proc, child, timeout=30)
    assert proc.returncode == 1
    assert "the shutdown grace of 0.5 s ended" in err


def test_the_end_of_the_parent_pipe_ends_a_stuck_process(tmp_path):
    read, write = os.pipe()
    proc, child = _stuck(tmp_path, grace=120, pass_fd=read)
    os.close(read)
    time.sleep(0.3)
    assert proc.poll() is None
    os.close(write)  # what the death of the parent does
    err = _finish(proc, child, timeout=30)
    assert proc.returncode == 1
    assert "the process that started it" in err


def test_children_and_a_negative_grace():
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        assert sleeper.pid in children(os.getpid())
    finally:
        sleeper.kill()
        sleeper.wait()
    assert sleeper.pid not in children(os.getpid())
    with pytest.raises(ValueError, match="grace"):
        ShutdownGuard(-1.0)
