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
    # the placeholders of what no engine command uses stand to the end (never asked anything)
    assert {"numpy.f2py", "numpy.testing", "yaml"} <= set(loaded)
    assert "numpy.f2py.crackfortran" not in loaded and "numpy.testing._private" not in loaded
    assert "yaml.loader" not in loaded
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


#: Not needed by any method before its synthesis: the plots' library, the service, and SciPy's signal
#: processing, optimisation and integration (``scipy.signal`` alone loads ``scipy.stats``,
#: ``scipy.optimize`` and ``scipy.interpolate``: 0.1-0.2 s of a command's single-threaded start).
NOT_BEFORE_ANY_SYNTHESIS = ("matplotlib", "fastapi", "celery", "redis", "scipy.signal")
#: The pixel driver and its kernels, which the patch methods do not run.
PIXEL_DRIVER = ("texsynth.synth.pixel.synthesis", "texsynth.synth.kernels.pixel_search")
NO_STATS = ("scipy.stats", "scipy.optimize", "scipy.integrate", "scipy.interpolate")


@pytest.mark.parametrize(
    ("method", "size", "absent"),
    [
        ("tensor-constrained", "32x32", (*NO_STATS, "texsynth.synth.kernels.patch_search")),
        ("quilting", "64x64", (*NO_STATS, *PIXEL_DRIVER, "texsynth.synth.pixel.solid")),
        ("gaussian-patch", "64x64", (*NO_STATS, *PIXEL_DRIVER)),
        ("solid-kopf", "16x16x16", (*NO_STATS, "texsynth.synth.kernels.patch_search")),
        # skimage.restoration's bilateral filter (its feature map) does load scipy.stats
        ("feature-guided", "64x64", PIXEL_DRIVER),
    ],
)
def test_what_a_command_imports_before_its_synthesis(
    method: str, size: str, absent: tuple[str, ...], exemplar: Path, tmp_path: Path
) -> None:
    """The modules of a ``texsynth synthesize`` process when its synthesis starts (the command's own
    path: parsing, the method's module, the writer, the inputs), stopped there."""
    loaded = _fresh(
        """
        import json, os, sys
        import texsynth.synth.api as api

        def stop(*args, **kwargs):  # the synthesis starts: what is loaded, then out
            print(json.dumps(sorted(sys.modules)), flush=True)
            os._exit(0)

        api.synthesize = stop  # before the pipeline imports it
        from texsynth.synth.cli import main
        main(["synthesize", sys.argv[1], "--exemplar", sys.argv[2], "--size", sys.argv[3],
              "--out", sys.argv[4], "--seed", "1"])
        raise SystemExit("the synthesis never started")
        """,
        method,
        str(exemplar),
        size,
        str(tmp_path / "run"),
    )
    assert f"texsynth.synth.methods.{method.replace('-', '_')}" in loaded  # stopped at the right place
    assert "texsynth.synth.output.artifacts" in loaded
    unwanted = NOT_BEFORE_ANY_SYNTHESIS + absent
    assert [m for m in loaded if m in unwanted or m.startswith(("texsynth.app", "texsynth.jobs"))] == []


def test_the_s2_comparison_imports_no_optimiser() -> None:
    """A volume's evaluation compares ``S2`` curves (FFT) without ``scipy.integrate`` and
    ``scipy.optimize`` (0.05-0.1 s); the level-cut model that needs them still loads them itself."""
    found = _fresh(
        """
        import json, sys
        import numpy as np
        from texsynth.synth.evaluate.correlation import compare_s2, image_s2, level_cut_s2, volume_s2

        rng = np.random.default_rng(0)
        exemplar, volume = rng.random((24, 24)), rng.random((12, 12, 12))
        s2 = volume_s2(volume)
        compare_s2(image_s2(exemplar)["row"], s2["z"])
        before = [m for m in ("scipy.integrate", "scipy.optimize") if m in sys.modules]
        value = float(level_cut_s2(np.array([0.0]), 3.0, 0.25)[0])
        print(json.dumps({"before": before, "value": value, "after": "scipy.integrate" in sys.modules}))
        """
    )
    assert found["before"] == []
    assert found["value"] == pytest.approx(0.25)  # S2(0) is the volume fraction
    assert found["after"]


def test_a_module_on_demand_loads_at_its_first_attribute_from_any_thread() -> None:
    """:func:`texsynth.synth.cli.modules_on_demand`: ``from numpy import *`` (SciPy's array-API layer)
    binds the placeholders without loading them; the first attribute asked loads the real module, which
    then stands in ``sys.modules`` and on ``numpy``; eight threads asking at once all get their answer."""
    seen = _fresh(
        """
        import json, sys, threading
        from texsynth.synth.cli import modules_on_demand
        modules_on_demand()
        modules_on_demand()  # twice: nothing more
        import numpy
        from numpy import *  # noqa: F403
        import scipy.ndimage
        before = {n: type(sys.modules[n]).__name__ for n in ("numpy.f2py", "numpy.testing", "yaml")}
        crack = "numpy.f2py.crackfortran" in sys.modules
        import numpy.testing as placeholder
        answers = []
        def ask():
            answers.append(placeholder.assert_array_equal is sys.modules["numpy.testing"].assert_array_equal)
        threads = [threading.Thread(target=ask) for _ in range(8)]
        for t in threads: t.start()
        for t in threads: t.join()
        import yaml
        print(json.dumps({
            "before": before, "crack": crack, "answers": answers,
            "after": type(sys.modules["numpy.testing"]).__name__,
            "attribute": numpy.testing is sys.modules["numpy.testing"],
            "real": hasattr(sys.modules["numpy.testing"], "__file__"),
            "yaml": yaml.safe_load("a: 1"),
            "f2py": type(sys.modules["numpy.f2py"]).__name__,
        }))
        """
    )
    assert seen["before"] == {"numpy.f2py": "_OnDemand", "numpy.testing": "_OnDemand", "yaml": "_OnDemand"}
    assert not seen["crack"]
    assert seen["answers"] == [True] * 8
    assert seen["after"] == "module" and seen["attribute"] and seen["real"]
    assert seen["yaml"] == {"a": 1}
    assert seen["f2py"] == "_OnDemand"  # never asked: never loaded
