"""The numba hot loops: each private ``_x_kernel`` beside its plain NumPy ``x_reference``, which the tests
compare it with. Every kernel is compiled with :mod:`texsynth.synth.kernels.options`."""
