"""Job records, queue settings, method registry and reaper: what the API (``app``) and the worker
(``worker``) share about a job."""
