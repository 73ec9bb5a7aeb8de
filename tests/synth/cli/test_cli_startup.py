"""A fast command: each command imports only what it needs (checked in fresh processes).

Import times are never asserted (the machine is shared); what is pinned is which modules a fresh
process holds after building the parser, after a synthesis, and what a second job in the same process
adds (nothing: no module, no compiled kernel).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.paths import REPO

HEAVY = ("numpy", "numba", "scipy", "matplotlib", "pydantic", "skimage", "celery", "fastapi")


def _fresh(code: str, *args: str) -> dict:
    """Run ``code`` in a fresh interpreter at the checkout's root; it prints one JSON document."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code), *args],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _top_level(modules: list[str]) -> set[str]:
    return {m.split(".")[0] for m in modules}


def test_building_the_parser_imports_no_engine() -> None:
    loaded = _fresh(
        """
        import json, sys
        from texsynth.synth.cli import build_parser
        build_parser()  # every command, the entry points' too (texsynth --help)
        full = sorted(sys.modules)
        build_parser("synthesize")
        print(json.dumps(full))
        """
    )
    assert _top_level(loaded).isdisjoint(HEAVY), sorted(_top_level(loaded) & set(HEAVY))
    heavy_own = ("texsynth.synth.kernels", "texsynth.synth.methods", "texsynth.synth.output")
    assert not [m for m in loaded if m.startswith(heavy_own)]


def test_cli_planes_are_the_engines() -> None:
    from texsynth.synth.api import PLANES
    from texsynth.synth.cli.inputs import PLANES as CLI_PLANES

    assert CLI_PLANES == PLANES


def test_synthesize_imports_one_method_and_no_matplotlib(exemplar: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    loaded = _fresh(
        """
        import json, sys
        from texsynth.synth.cli import main
        code = main(["synthesize", "tensor-constrained", "--exemplar", sys.argv[1], "--size", "48x48",
                     "--set", "neighbourhood_size=5", "--out", sys.argv[2], "--seed", "1"])
        assert code == 0
        print(json.dumps(sorted(sys.modules)))
        """,
        str(exemplar),
        str(out),
    )
    prefix = "texsynth.synth.methods."
    methods = {m for m in loaded if m.startswith(prefix) and m != prefix + "common"}
    assert methods == {"texsynth.synth.methods.tensor_constrained"}
    assert "matplotlib" not in _top_level(loaded)
    assert "scipy.stats" not in loaded  # the exact KS test and the moments are computed without it
    # every artifact is still written, plots included
    for name in (
        "output.png",
        "output.tiff",
        "coherence.png",
        "orientation.png",
        "metrics.json",
        "manifest.json",
        "plots/grey_histogram.png",
        "plots/orientation_rose.png",
        "plots/fringe_distributions.png",
        "plots/fringes_exemplar.png",
        "plots/fringes_output.png",
    ):
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    assert metrics["fringes"]["ks_length"]["pvalue"] is not None


def test_a_second_job_in_a_process_imports_and_compiles_nothing(exemplar: Path, tmp_path: Path) -> None:
    """What the worker does per job (``synthesize_to_folder``): the second run adds no module and no
    compiled kernel to the process."""
    added = _fresh(
        """
        import json, sys
        from pathlib import Path
        from texsynth.synth.pipeline import load_inputs, synthesize_to_folder

        def kernels():
            from numba.core.registry import CPUDispatcher
            found = {}
            for name, module in list(sys.modules.items()):
                if name.startswith("texsynth.synth.") and module is not None:
                    for attr, value in vars(module).items():
                        if isinstance(value, CPUDispatcher):
                            found[f"{name}.{attr}"] = len(value.overloads)
            return found

        images = load_inputs({"exemplar": Path(sys.argv[1])})
        job = dict(size=(40, 40), params={"neighbourhood_size": 5}, seed=1)
        synthesize_to_folder("tensor-constrained", images, Path(sys.argv[2]) / "a", **job)
        before, compiled = set(sys.modules), kernels()
        synthesize_to_folder("tensor-constrained", images, Path(sys.argv[2]) / "b", **job)
        print(json.dumps({"modules": sorted(set(sys.modules) - before),
                          "kernels": sorted(k for k, n in kernels().items() if compiled.get(k) != n),
                          "used": sum(n > 0 for n in compiled.values())}))
        """,
        str(exemplar),
        str(tmp_path),
    )
    assert added["used"] > 0  # the first job did run compiled kernels (loaded from numba's cache)
    assert added["modules"] == [] and added["kernels"] == []


@pytest.mark.parametrize("method", ["wei_levoy", "tensor_constrained", "arbitrary_shape", "quilting"])
def test_a_2d_method_imports_no_solid_driver_and_no_service(method: str) -> None:
    """A 2D method's module brings neither the solid driver (its kernels, its caches) nor the plots'
    or the service's libraries; the solid methods still get their planes checked."""
    loaded = _fresh(
        f"""
        import json, sys
        import texsynth.synth.methods.{method}
        print(json.dumps(sorted(sys.modules)))
        """
    )
    solid = [
        m for m in loaded if m.startswith(("texsynth.synth.pixel.solid", "texsynth.synth.kernels.solid"))
    ]
    assert solid == []
    assert _top_level(loaded).isdisjoint({"matplotlib", "celery", "fastapi", "redis"})
    assert not [m for m in loaded if m.startswith(("texsynth.app", "texsynth.jobs", "texsynth.worker"))]


def test_solid_params_still_check_their_planes() -> None:
    from pydantic import ValidationError

    from texsynth.synth.methods.common import SolidParams

    assert SolidParams(planes=("yz", "xz")).planes == ("xz", "yz")
    with pytest.raises(ValidationError, match="planes"):
        SolidParams(planes=("xy", "xy"))
