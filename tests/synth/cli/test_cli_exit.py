"""The ``texsynth`` program's cheap start and end: the cycle collector off while a command imports, and a
quick exit after a one-shot engine command (output flushed, ``atexit`` run, the command's status kept).

What is pinned is behaviour, never a time (the machine is shared).
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.paths import REPO
from texsynth.synth.cli import imports_without_gc, main


def _program(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter (stdout a pipe, as a script's caller reads it)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code), *args],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_imports_without_gc_freezes_what_was_imported_and_turns_the_collector_back_on() -> None:
    assert gc.isenabled()
    frozen = gc.get_freeze_count()
    try:
        with imports_without_gc():
            assert not gc.isenabled()
            with imports_without_gc():  # nested: left to the outer block
                assert not gc.isenabled()
            assert not gc.isenabled()
            kept = [[i] for i in range(1000)]  # noqa: F841  (objects alive at the end of the block)
        assert gc.isenabled()
        assert gc.get_freeze_count() >= frozen + 1000
    finally:
        gc.unfreeze()


def test_imports_without_gc_leaves_a_disabled_collector_alone() -> None:
    gc.disable()
    try:
        frozen = gc.get_freeze_count()
        with imports_without_gc():
            pass
        assert not gc.isenabled()
        assert gc.get_freeze_count() == frozen
    finally:
        gc.enable()


def test_main_in_a_process_leaves_nothing_frozen(capsys: pytest.CaptureFixture[str]) -> None:
    """A caller that goes on running (tests, a notebook) gets its collector as it was."""
    assert main(["methods"]) == 0
    assert "wei-levoy" in capsys.readouterr().out
    assert gc.isenabled()
    assert gc.get_freeze_count() == 0


def test_the_program_exits_quickly_with_its_output_flushed_and_atexit_run(
    exemplar: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    done = _program(
        """
        import atexit, sys
        atexit.register(lambda: print("atexit ran", flush=True))
        sys.argv = ["texsynth", "synthesize", "wei-levoy", "--exemplar", sys.argv[1], "--size", "48x48",
                    "--set", "neighbourhood_size=5", "--set", "levels=2", "--seed", "1", "--out", sys.argv[2]]
        from texsynth.synth.cli import entry
        entry()
        print("not reached")
        """,
        str(exemplar),
        str(out),
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("wei-levoy: 48x48 in ")  # the summary, flushed although stdout is a pipe
    assert lines[-1] == "atexit ran"
    assert "not reached" not in done.stdout
    metrics = json.loads((out / "metrics.json").read_text())  # every file whole
    assert metrics["metrics"]["summary"]
    assert (out / "plots" / "grey_histogram.png").stat().st_size > 0


def test_the_program_keeps_an_error_status(tmp_path: Path) -> None:
    done = _program(
        """
        import sys
        sys.argv = ["texsynth", "synthesize", "no-such-method", "--exemplar", "x.png", "--out", sys.argv[1]]
        from texsynth.synth.cli import entry
        entry()
        """,
        str(tmp_path / "run"),
    )
    assert done.returncode == 2
    assert "METHOD" in done.stderr and "unknown method" in done.stderr


def test_python_dash_m_runs_the_program(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "texsynth.synth.cli", "methods"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert "tensor-constrained" in done.stdout


def test_a_run_that_does_not_fit_in_memory_says_so_without_a_traceback(monkeypatch, capsys) -> None:
    """A MemoryError (NumPy's 'Unable to allocate ...') is the machine's limit, not a crash: exit 1 and one
    line that says what to ask for instead."""
    import texsynth.synth.cli.synthesize as command

    def fail(args):  # type: ignore[no-untyped-def]
        raise MemoryError("Unable to allocate 37.1 GiB for an array with shape (57600, 57600, 3)")

    monkeypatch.setattr(command, "_run", fail)
    code = main(["synthesize", "wei-levoy", "--exemplar", "x.png", "--out", "never"])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    assert err.strip().startswith("texsynth synthesize: error: not enough memory for this run (Unable")
    assert "smaller output" in err
