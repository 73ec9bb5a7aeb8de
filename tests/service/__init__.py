"""Integration tests of the job service: API + real worker processes + real broker."""
