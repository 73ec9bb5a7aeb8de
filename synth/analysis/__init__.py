"""Structure tensors, coherence, orientation and tensor metrics; rotation of images and tensor fields; HRTEM
lattice fringes."""
