"""The REST API under ``/api``: one router per resource in :mod:`app.api.routes`."""
