"""Keep a patch method's per-wave arrays on malloc's heap instead of fresh pages from the system.

A wave of a patch method (:meth:`texsynth.synth.patch.layout.PatchLayout.waves`) allocates and frees a few
arrays of one to a few MB: the padded templates, their spectra, the correlations, the errors and the
candidate lists of :meth:`texsynth.synth.patch.search.PatchSearcher.search_many`. glibc's ``malloc``
serves a block above its ``mmap`` threshold (128 KiB at start) with fresh pages from the system and
gives them back when it is freed; it raises the threshold to the size of a freed block of that kind
(up to 32 MiB; mallopt(3), ``M_MMAP_THRESHOLD``) and trims its heap when more than twice the threshold
is free at its top. In a fresh process the blocks of every wave were therefore new pages again:
quilting 1024^2 took 240 000 page faults and 0.3-0.36 s of system time (out of 1.0 s of CPU) the first
time, 3 000 faults in the same process afterwards (docs/patch.md, "Threads"). :func:`settle_heap` frees
one untouched block of the wave's size at the start, which raises the threshold as the first wave would
have, at no cost (the block's pages are never touched). Other C libraries: a harmless allocation.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_SETTLE", "settle_heap", "wave_batch", "wave_bytes"]

#: glibc's largest dynamic ``mmap`` threshold on 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX``).
MAX_SETTLE = 32 << 20


def wave_bytes(patches: int, grid: tuple[int, int], channels: int) -> int:
    """The bytes one wave of ``patches`` searches allocates (an upper estimate): per patch, the template
    padded to the exemplar's ``grid`` and its spectra (``16 C`` bytes a grid point), the spectral product and
    the correlation (16), the errors, SSDs and candidates (24)."""
    return int(patches) * int(grid[0]) * int(grid[1]) * (16 * int(channels) + 40)


def wave_batch(grid: tuple[int, int], channels: int, threads: int) -> int:
    """How many patches one thread searches at a time, so that the arrays of the searches running at once on
    ``threads`` threads stay within :data:`MAX_SETTLE` (a 4096^2 output's waves hold 150 patches: searched
    whole, they freed more than glibc keeps, and every wave took fresh pages again)."""
    return max(1, MAX_SETTLE // (max(1, int(threads)) * wave_bytes(1, grid, channels)))


def settle_heap(nbytes: int) -> int:
    """Allocate and free one block of ``nbytes`` (at most :data:`MAX_SETTLE`; nothing below 1 MiB), so that
    glibc's ``malloc`` serves blocks up to that size from its heap and keeps twice that much when they are
    freed (see the module docstring). Returns the size used (0: nothing done). Touches no page."""
    size = min(int(nbytes), MAX_SETTLE)
    if size < 1 << 20:
        return 0
    block = np.empty(size, dtype=np.uint8)
    del block
    return size
