"""A worker child imports what a job needs once, when it starts, not in its first job."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from tests.paths import REPO


def test_child_start_imports_the_methods_and_the_writer(tmp_path) -> None:
    code = textwrap.dedent(
        """
        import json, sys
        import texsynth.worker.celery_app as app
        wanted = ("texsynth.synth.output.artifacts", "texsynth.synth.evaluate.measures",
                  "texsynth.synth.output.plots", "texsynth.synth.methods.wei_levoy",
                  "texsynth.synth.methods.tensor_constrained")
        before = [m for m in wanted if m in sys.modules]
        app._on_child_start()
        after = [m for m in wanted if m in sys.modules]
        print(json.dumps({"before": sorted(before), "after": after,
                          "matplotlib": "matplotlib" in sys.modules}))
        """
    )
    env = {
        **os.environ,
        "PYTHONPATH": str(REPO),
        "TEXSYNTH_DATA_DIR": str(tmp_path),
        "TEXSYNTH_WORKER_NICE": "0",
    }
    env.pop("REDIS_URL", None)
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["before"] == []  # the main process (which forks the children) stays light
    assert len(seen["after"]) == 5 and not seen["matplotlib"]
