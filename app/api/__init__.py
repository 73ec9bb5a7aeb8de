"""The REST API under ``/api``: one router per resource in :mod:`texsynth.app.api.routes`."""
