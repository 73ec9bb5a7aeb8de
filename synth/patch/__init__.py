"""Patch-based synthesis machinery: the raster layout of overlapping patches (:mod:`.layout`), the masked
search of every exemplar patch by FFT correlation (:mod:`.search`), the Efros-Freeman minimum-error
boundary cut (:mod:`.cut`) and the Kwatra graph-cut seam (:mod:`.graphcut`) that stitch a new patch into
the output, and the locally Gaussian patch models of Raad, Desolneux & Morel (LG, CLG, RCLG;
:mod:`.gaussian`). The methods ``quilting`` and ``gaussian-patch`` are thin compositions of these pieces.
"""
