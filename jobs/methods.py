"""The methods this service offers: the engine's registry plus any ``TEXSYNTH_EXTRA_METHODS`` modules.

``TEXSYNTH_EXTRA_METHODS`` (comma-separated module names) lets a deployment - or the test suite, with
its small ``tests.service.methods_for_tests`` - register more methods through ``texsynth.synth.api.register``.
The API and every worker import the same list, so a method is offered only where it can run.
"""

from __future__ import annotations

import importlib

from texsynth.jobs.config import Settings
from texsynth.synth.api import MethodSpec, available_methods

__all__ = ["methods"]

_loaded: set[str] = set()


def methods(settings: Settings) -> dict[str, MethodSpec]:
    """All methods by name, after importing ``settings.extra_methods`` (once per process)."""
    for module in settings.extra_methods:
        if module not in _loaded:
            importlib.import_module(module)
            _loaded.add(module)
    return available_methods()
