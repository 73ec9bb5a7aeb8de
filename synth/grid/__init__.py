"""N-dimensional machinery shared by every pixel method: Gaussian pyramids, neighbourhoods, scan orders."""
