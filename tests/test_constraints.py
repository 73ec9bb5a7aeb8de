"""The Docker image and the Makefile install pinned versions: constraints.txt pins every runtime
dependency exactly."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _name(requirement: str) -> str:
    return re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower().replace("_", "-")


def test_every_runtime_dependency_is_pinned_and_the_image_uses_the_pins() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, version = line.partition("==")
            assert version, f"constraints.txt: {line!r} is not an exact pin"
            pins[_name(name)] = version
    runtime = project["dependencies"] + project["optional-dependencies"]["cluster"]
    missing = [dep for dep in runtime if _name(dep) not in pins]
    assert not missing, f"constraints.txt lacks {missing}: refresh it (see its header)"
    assert "pip install -c constraints.txt '.[cluster]'" in (ROOT / "Dockerfile").read_text()
    assert "pip install --quiet -c constraints.txt -e '.[dev]'" in (ROOT / "Makefile").read_text()
