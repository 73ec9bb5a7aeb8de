"""Pixel-by-pixel synthesis: search-state preparation around the numba search kernel, level by level."""
