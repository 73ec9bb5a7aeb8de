"""Known answers for :mod:`texsynth.synth.analysis.tensor`: gratings, noise, rotations, metrics and two
references.

Conventions pinned here (ALGORITHMS.md, "Conventions"): ``x`` = column, ``y = -row`` (up on
screen); orientations are radians counter-clockwise from +x, wrapped to ``(-pi/2, pi/2]``;
:func:`texsynth.synth.analysis.tensor.orientation` is the gradient direction,
:func:`texsynth.synth.analysis.tensor.structure_direction` the fringe direction, 90 degrees away.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg
from scipy import ndimage as ndi
from skimage.feature import structure_tensor as skimage_structure_tensor

from texsynth.synth.analysis.tensor import (
    LOG_EPSILON,
    METRICS,
    coherence,
    dominant_orientation,
    eigenvalues,
    neighbourhood_dissimilarity,
    orientation,
    orientation_histogram,
    rotate_tensors,
    structure_direction,
    structure_tensor,
    tensor_dissimilarity,
    wrap_angle,
)
from texsynth.synth.errors import InvalidParameter

ONE_DEGREE = np.radians(1.0)
# Gratings: the period and the border strip left out of "interior" comparisons (> 4 sigma_w).
PERIOD = 8.0
SIZE = 96
MARGIN = 16
INTERIOR = (slice(MARGIN, -MARGIN), slice(MARGIN, -MARGIN))
# Grating angles, including both sides of the +-90 degree wrap.
ANGLES_DEG = [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 89.0, 90.0, -89.0, -45.0, -30.0, -10.0]


def grating(theta: float, size: int = SIZE, period: float = PERIOD, dtype: type = np.float64) -> np.ndarray:
    """``sin(2 pi (x cos t + y sin t) / period)`` with ``x = col``, ``y = -row``; gradient along ``t``."""
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    x, y = cols, -rows
    phase = 2 * np.pi * (x * np.cos(theta) + y * np.sin(theta)) / period
    return (0.5 + 0.5 * np.sin(phase)).astype(dtype)


def angle_error(a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
    """Absolute difference of two orientations, modulo pi (so +90 and -90 degrees agree)."""
    return np.abs(wrap_angle(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)))


def smooth_field(size: int = 128, sigma: float = 4.0, seed: int = 1) -> np.ndarray:
    """Gaussian-blurred white noise rescaled to [0, 1]: smooth, with orientations of every kind."""
    noise = np.random.default_rng(seed).standard_normal((size, size))
    field = ndi.gaussian_filter(noise, sigma, mode="reflect")
    return (field - field.min()) / (field.max() - field.min())


def random_spd(n: int, seed: int = 0) -> np.ndarray:
    """``n`` random symmetric positive definite tensors ``(S_xx, S_xy, S_yy)``, float64."""
    m = np.random.default_rng(seed).standard_normal((n, 2, 2))
    spd = m @ np.swapaxes(m, 1, 2) + 0.05 * np.eye(2)
    return np.stack([spd[:, 0, 0], spd[:, 0, 1], spd[:, 1, 1]], axis=-1)


def as_matrix(t: np.ndarray) -> np.ndarray:
    return np.array([[t[0], t[1]], [t[1], t[2]]])


# --- wrap_angle -------------------------------------------------------------------------------


def test_wrap_angle_range_and_endpoints() -> None:
    a = np.linspace(-3 * np.pi, 3 * np.pi, 1001)
    w = wrap_angle(a)
    assert np.all(w > -np.pi / 2) and np.all(w <= np.pi / 2 + 1e-12)
    np.testing.assert_allclose(np.sin(2 * w), np.sin(2 * a), atol=1e-12)  # same orientation
    np.testing.assert_allclose(
        wrap_angle(np.array([-np.pi / 2, np.pi / 2, np.pi])), [np.pi / 2, np.pi / 2, 0]
    )


# --- gratings ---------------------------------------------------------------------------------


@pytest.mark.parametrize("theta_deg", ANGLES_DEG)
def test_grating_orientation_coherence_and_fringe_direction(theta_deg: float) -> None:
    theta = np.radians(theta_deg)
    S = structure_tensor(grating(theta), sigma_d=1.0, sigma_w=3.0)
    O = orientation(S)[INTERIOR]
    assert angle_error(O, theta).max() < ONE_DEGREE
    assert np.all((-np.pi / 2 < O) & (np.pi / 2 >= O))
    assert coherence(S)[INTERIOR].min() > 0.95
    fringe = structure_direction(S)[INTERIOR]
    expected_fringe = wrap_angle(theta + np.pi / 2)
    assert angle_error(fringe, expected_fringe).max() < ONE_DEGREE
    assert np.all((fringe > -np.pi / 2) & (fringe <= np.pi / 2))


def test_vertical_fringes_have_gradient_zero_and_fringe_ninety() -> None:
    """Explicit wrap check: fringes running up the screen have a horizontal gradient."""
    S = structure_tensor(grating(0.0))
    assert abs(float(np.median(orientation(S)[INTERIOR]))) < 1e-6
    assert float(np.median(structure_direction(S)[INTERIOR])) == pytest.approx(np.pi / 2, abs=1e-6)


def test_y_axis_points_up() -> None:
    """Intensity increasing up the screen (decreasing row) has a gradient at +90 degrees, a ramp
    increasing along ``x = y`` (up-right on screen) one at +45 degrees."""
    rows, cols = np.mgrid[0:64, 0:64].astype(np.float64)
    S_up = structure_tensor((63 - rows) / 63)
    assert np.all(S_up[INTERIOR][..., 1] == pytest.approx(0.0, abs=1e-12))
    assert angle_error(orientation(S_up)[INTERIOR], np.pi / 2).max() < 1e-6
    S_diag = structure_tensor((cols - rows) / 126)
    assert np.all(S_diag[INTERIOR][..., 1] > 0)  # I_x I_y > 0: both derivatives positive
    assert angle_error(orientation(S_diag)[INTERIOR], np.pi / 4).max() < 1e-6


def test_isotropic_noise_has_low_coherence() -> None:
    noise = np.random.default_rng(7).standard_normal((192, 192))
    C = coherence(structure_tensor(noise, sigma_d=1.0, sigma_w=3.0))
    assert float(C.mean()) < 0.3


def test_rot90_rotates_orientation_by_plus_ninety() -> None:
    """``np.rot90`` turns the picture counter-clockwise on screen, so orientations gain +90 degrees.

    ``rot90(I)[i, j] = I[j, W-1-i]``: compare ``O(rot90(I))`` with ``rot90(O(I)) + pi/2``.
    """
    image = smooth_field(size=96, sigma=3.0, seed=3)
    S = structure_tensor(image)
    S_rot = structure_tensor(np.rot90(image))
    expected = wrap_angle(np.rot90(orientation(S)) + np.pi / 2)
    got = orientation(S_rot)
    mask = np.zeros(got.shape, dtype=bool)
    mask[INTERIOR] = True
    mask &= coherence(S_rot) > 0.2
    assert mask.sum() > 1000
    assert angle_error(got[mask], expected[mask]).max() < 1e-6
    np.testing.assert_allclose(coherence(S_rot), np.rot90(coherence(S)), atol=1e-9)


# --- Di Zenzo, dominant orientation, histogram, flat images -----------------------------------


def test_rgb_with_identical_channels_is_three_times_grey() -> None:
    grey = smooth_field(size=64, seed=5).astype(np.float32)
    rgb = np.repeat(grey[..., None], 3, axis=2)
    want = 3 * structure_tensor(grey)
    # float32: summing three channels rounds differently from one product times 3.
    np.testing.assert_allclose(structure_tensor(rgb), want, rtol=1e-5, atol=1e-6 * np.abs(want).max())


def test_rgb_sums_channel_tensors() -> None:
    rgb = np.stack([smooth_field(size=48, seed=s) for s in (10, 11, 12)], axis=-1)
    total = sum(structure_tensor(rgb[..., c]) for c in range(3))
    np.testing.assert_allclose(structure_tensor(rgb), total, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("theta_deg", [0.0, 30.0, 89.0, 90.0, -60.0])
def test_dominant_orientation_of_grating(theta_deg: float) -> None:
    theta = np.radians(theta_deg)
    S = structure_tensor(grating(theta))
    assert angle_error(dominant_orientation(S), theta) < ONE_DEGREE
    weights = coherence(S)
    assert angle_error(dominant_orientation(S, weights=weights), theta) < ONE_DEGREE


@pytest.mark.parametrize("theta_deg", [0.0, 30.0, -45.0, 85.0])
def test_orientation_histogram_sums_to_one_and_peaks_at_theta(theta_deg: float) -> None:
    theta = np.radians(theta_deg)
    S = structure_tensor(grating(theta))
    for weight in ("energy", "none"):
        hist, edges = orientation_histogram(S, bins=36, weight=weight)
        assert hist.shape == (36,) and edges.shape == (37,)
        assert hist.sum() == pytest.approx(1.0)
        assert edges[0] == pytest.approx(-np.pi / 2) and edges[-1] == pytest.approx(np.pi / 2)
        peak = int(np.argmax(hist))
        centre = 0.5 * (edges[peak] + edges[peak + 1])
        assert angle_error(centre, theta) <= np.pi / 36 + 1e-9  # within one bin width


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_flat_image_has_zero_coherence_and_no_nan(dtype: type) -> None:
    S = structure_tensor(np.full((32, 32), 0.4, dtype=dtype))
    assert S.dtype == dtype
    for field in (coherence(S), orientation(S), structure_direction(S)):
        assert np.all(np.isfinite(field))
    assert np.all(coherence(S) == 0)
    hist, _ = orientation_histogram(S, bins=12)
    assert np.all(np.isfinite(hist)) and hist.sum() == pytest.approx(1.0)
    assert np.isfinite(dominant_orientation(S))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint8])
def test_dtype_policy(dtype: type) -> None:
    image = (grating(0.3) * (255 if dtype == np.uint8 else 1)).astype(dtype)
    S = structure_tensor(image)
    assert S.shape == (*image.shape, 3)
    assert S.dtype == (np.float32 if dtype == np.uint8 else dtype)


def test_structure_tensor_rejects_bad_input() -> None:
    with pytest.raises(InvalidParameter, match="sigma_d"):
        structure_tensor(np.zeros((8, 8)), sigma_d=0.0)
    with pytest.raises(InvalidParameter, match="sigma_w"):
        structure_tensor(np.zeros((8, 8)), sigma_w=-1.0)
    for bad in (np.inf, np.nan):
        with pytest.raises(InvalidParameter, match="sigma_d"):
            structure_tensor(np.zeros((8, 8)), sigma_d=bad)
    with pytest.raises(InvalidParameter, match="image"):
        structure_tensor(np.zeros(8))


# --- references: a plain correlation, and scikit-image ---------------------------------------


def _gaussian_kernels(sigma: float, truncate: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """Sampled Gaussian ``g`` (sum 1) and the correlation kernel of its derivative, ``x g / sigma^2``.

    Correlating with ``x g(x) / sigma^2`` is convolving with ``G'(x) = -x g(x) / sigma^2``: the
    derivative of the Gaussian-smoothed image (positive on a rising ramp). Radius as scipy's.
    """
    radius = int(truncate * sigma + 0.5)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    g = np.exp(-0.5 * x**2 / sigma**2)
    g /= g.sum()
    return g, x * g / sigma**2


def structure_tensor_reference(image: np.ndarray, sigma_d: float, sigma_w: float, mode: str) -> np.ndarray:
    """Akl 2014 eqs 1-3 spelled out with 2D kernels: ``Ix = I * G_x``, ``Iy = -dI/drow``, window."""
    g, dg = _gaussian_kernels(sigma_d)
    image = image.astype(np.float64)
    ix = ndi.correlate(image, np.outer(g, dg), mode=mode)
    iy = -ndi.correlate(image, np.outer(dg, g), mode=mode)
    w, _ = _gaussian_kernels(sigma_w)
    window = np.outer(w, w)
    return np.stack([ndi.correlate(p, window, mode=mode) for p in (ix * ix, ix * iy, iy * iy)], axis=-1)


@pytest.mark.parametrize(
    ("sigma_d", "sigma_w", "mode"), [(1.0, 3.0, "reflect"), (0.7, 2.0, "wrap"), (2.0, 5.0, "nearest")]
)
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_structure_tensor_matches_plain_correlation(
    sigma_d: float, sigma_w: float, mode: str, dtype: type
) -> None:
    image = smooth_field(size=80, sigma=2.0, seed=4).astype(dtype)
    got = structure_tensor(image, sigma_d, sigma_w, mode=mode)
    ref = structure_tensor_reference(image, sigma_d, sigma_w, mode)
    scale = np.abs(ref).max()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-5 * scale)


def test_agrees_with_skimage_structure_tensor() -> None:
    """Cross-check with :func:`skimage.feature.structure_tensor` (``order='rc'``).

    scikit-image differentiates with Sobel (``ndi.sobel``): a central difference ``[-1, 0, 1]``
    (twice the derivative) times a ``[1, 2, 1]`` smoothing across (sum 4), i.e. 8x the gradient,
    then windows the products with a Gaussian of ``sigma``. Its axes are rows (down) and columns,
    ours ``x = col`` and ``y = -row``, so with the same window sigma and border mode::

        S_xx ~ A_cc / 64,    S_yy ~ A_rr / 64,    S_xy ~ -A_rc / 64.

    Sobel is not a Gaussian derivative, so the two agree only where the image is smooth at the pixel
    scale (here Gaussian-blurred noise, sigma 4). For low frequencies ``w`` the central difference
    responds like a Gaussian derivative of variance 1/3 (``sin w / w ~ 1 - w^2/6``) and the
    ``[1, 2, 1]/4`` smoothing like a Gaussian of variance 1/2 (``cos^2(w/2) ~ 1 - w^2/4``); an
    isotropic Gaussian derivative matches both best at ``sigma_d^2 ~ (1/3 + 1/2) / 2``, i.e.
    ``sigma_d ~ 0.65`` (measured: ~2% component error there, ~7% at ``sigma_d = 1``, and 25% at 0.5
    where the sampled Gaussian no longer has the variance its sigma says).
    """
    image = smooth_field(size=160, sigma=4.0, seed=1)
    sigma_w = 3.0
    a_rr, a_rc, a_cc = skimage_structure_tensor(image, sigma=sigma_w, mode="reflect", order="rc")
    ref = np.stack([a_cc / 64, -a_rc / 64, a_rr / 64], axis=-1)
    S = structure_tensor(image, sigma_d=0.65, sigma_w=sigma_w, mode="reflect")
    inner = (slice(12, -12), slice(12, -12))
    for k in range(3):
        rel = np.linalg.norm(S[inner][..., k] - ref[inner][..., k]) / np.linalg.norm(ref[inner][..., k])
        assert rel < 0.04, f"component {k}: relative error {rel:.3f}"
    C, C_ref = coherence(S)[inner], coherence(ref)[inner]
    assert np.abs(C - C_ref).max() < 0.02
    coherent = C_ref > 0.3
    assert coherent.mean() > 0.5
    assert angle_error(orientation(S)[inner][coherent], orientation(ref)[inner][coherent]).max() < ONE_DEGREE


# --- rotation ---------------------------------------------------------------------------------


def test_rotate_tensors_scalar_angle() -> None:
    S = structure_tensor(smooth_field(size=64, seed=8))
    angle = np.radians(37.0)
    R = rotate_tensors(S, angle)
    assert R.shape == S.shape and R.dtype == S.dtype
    strong = coherence(S) > 0.1
    assert angle_error(orientation(R)[strong], orientation(S)[strong] + angle).max() < 1e-9
    for got, want in zip(eigenvalues(R), eigenvalues(S), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(coherence(R), coherence(S), atol=1e-9)


def test_rotate_tensors_per_pixel_angles() -> None:
    S = structure_tensor(grating(0.0, size=48))
    angles = np.random.default_rng(2).uniform(-np.pi, np.pi, size=S.shape[:2])
    R = rotate_tensors(S, angles)
    inner = (slice(12, -12), slice(12, -12))
    assert angle_error(orientation(R)[inner], angles[inner]).max() < 1e-6
    np.testing.assert_allclose(coherence(R), coherence(S), atol=1e-9)
    # The same rotation as a matrix product R S R^T with R = [[c, -s], [s, c]] (y up).
    i, j = 20, 31
    c, s = np.cos(angles[i, j]), np.sin(angles[i, j])
    rot = np.array([[c, -s], [s, c]])
    np.testing.assert_allclose(as_matrix(R[i, j]), rot @ as_matrix(S[i, j]) @ rot.T, rtol=1e-12)


def test_rotating_a_grating_tensor_field_matches_the_rotated_grating() -> None:
    theta, angle = np.radians(20.0), np.radians(50.0)
    rotated = rotate_tensors(structure_tensor(grating(theta)), angle)
    direct = structure_tensor(grating(theta + angle))
    assert angle_error(orientation(rotated)[INTERIOR], orientation(direct)[INTERIOR]).max() < ONE_DEGREE


# --- dissimilarities --------------------------------------------------------------------------


def test_log_euclidean_matches_scipy_logm() -> None:
    t1, t2 = random_spd(40, seed=0), random_spd(40, seed=1)
    got = tensor_dissimilarity(t1, t2, "LE")
    eye = np.eye(2)
    for k in range(len(t1)):
        l1 = np.real(linalg.logm(as_matrix(t1[k]) + LOG_EPSILON * eye))
        l2 = np.real(linalg.logm(as_matrix(t2[k]) + LOG_EPSILON * eye))
        assert got[k] == pytest.approx(np.linalg.norm(l1 - l2, "fro"), abs=1e-8)


def test_euclidean_distance_equals_eq6_on_hand_values() -> None:
    a = np.array([1.0, 2.0, 3.0])
    b = np.array([0.5, -1.0, 4.0])
    # (a11 - b11)^2 + (a22 - b22)^2 + 2 (a12 - b12)^2 = 0.25 + 1 + 2 * 9
    assert float(tensor_dissimilarity(a, b, "ED")) == pytest.approx(19.25)
    assert float(tensor_dissimilarity(a, b, "FN")) == pytest.approx(np.sqrt(19.25))
    assert float(tensor_dissimilarity(a, b, "FN")) == pytest.approx(
        np.linalg.norm(as_matrix(a) - as_matrix(b))
    )


def test_frobenius_is_square_root_of_euclidean() -> None:
    t1, t2 = random_spd(50, seed=3), random_spd(50, seed=4)
    np.testing.assert_allclose(
        tensor_dissimilarity(t1, t2, "FN"), np.sqrt(tensor_dissimilarity(t1, t2, "ED")), rtol=1e-12
    )


@pytest.mark.parametrize("metric", METRICS)
def test_metrics_symmetric_and_zero_on_identical(metric: str) -> None:
    t1, t2 = random_spd(30, seed=5), random_spd(30, seed=6)
    d12 = tensor_dissimilarity(t1, t2, metric)
    d21 = tensor_dissimilarity(t2, t1, metric)
    np.testing.assert_allclose(d12, d21, rtol=1e-12, atol=1e-15)
    assert np.all(d12 >= 0)
    np.testing.assert_allclose(tensor_dissimilarity(t1, t1, metric), 0.0, atol=1e-12)


def test_structure_orientation_metric_parts() -> None:
    """SO = M_or^alpha M_coh^(1-alpha), M_or = |sin(O1-O2)| min(C1, C2), M_coh = max(C1/C2, C2/C1)."""
    base = np.array([2.0, 0.0, 0.5])  # orientation 0, coherence 0.6
    other = rotate_tensors(np.array([4.0, 0.0, 1.0]), np.radians(30.0))  # orientation 30, coherence 0.6
    c = 1.5 / 2.5
    assert float(tensor_dissimilarity(base, other, "SO", alpha=1.0)) == pytest.approx(0.5 * c)
    assert float(tensor_dissimilarity(base, other, "SO", alpha=0.0)) == pytest.approx(1.0)
    weak = np.array([1.0, 0.0, 0.6])  # orientation 0, coherence 0.25
    assert float(tensor_dissimilarity(base, weak, "SO", alpha=0.0)) == pytest.approx(c / 0.25)
    flat = np.zeros(3)  # zero coherence is floored, never a division by zero
    assert np.isfinite(tensor_dissimilarity(base, flat, "SO", alpha=0.5))


@pytest.mark.parametrize("alpha", [-0.1, 1.5, np.nan])
def test_structure_orientation_alpha_out_of_range(alpha: float) -> None:
    t = random_spd(2)
    with pytest.raises(InvalidParameter, match="alpha"):
        tensor_dissimilarity(t, t, "SO", alpha=alpha)


def test_unknown_metric() -> None:
    t = random_spd(2)
    with pytest.raises(InvalidParameter, match=r"metric.*must be one of ED, SO, FN, LE"):
        tensor_dissimilarity(t, t, "L2")  # type: ignore[arg-type]


@pytest.mark.parametrize("metric", METRICS)
def test_neighbourhood_dissimilarity_is_sum_over_tensors(metric: str) -> None:
    f1 = random_spd(5 * 9, seed=7).reshape(5, 9, 3)
    f2 = random_spd(5 * 9, seed=8).reshape(5, 9, 3)
    np.testing.assert_allclose(
        neighbourhood_dissimilarity(f1, f2, metric), tensor_dissimilarity(f1, f2, metric).sum(axis=-1)
    )


def test_mean_coherence_of_stripes_noise_and_rgb() -> None:
    """Straight stripes are fully oriented, white noise is not, and RGB is measured on its grey."""
    from texsynth.synth.analysis.tensor import ORIENTED_COHERENCE, mean_coherence

    _, x = np.mgrid[0:64, 0:64]
    stripes = (0.5 + 0.5 * np.sin(2 * np.pi * x / 8.0)).astype(np.float32)
    noise = np.random.default_rng(0).random((64, 64)).astype(np.float32)
    assert mean_coherence(stripes) > 0.95 > ORIENTED_COHERENCE > mean_coherence(noise)
    rgb = np.repeat(stripes[..., None], 3, axis=2)
    assert mean_coherence(rgb) == pytest.approx(mean_coherence(stripes), abs=1e-6)


def test_stack_tensor_is_each_image_tensor_bit_for_bit() -> None:
    from texsynth.synth.analysis.tensor import structure_tensor_stack

    rng = np.random.default_rng(4)
    stack = ndi.gaussian_filter(rng.random((6, 33, 41)), 1.2)
    for dtype in (np.float64, np.float32):
        for mode in ("reflect", "wrap"):
            got = structure_tensor_stack(stack.astype(dtype), 1.0, 2.0, mode=mode)
            want = np.stack([structure_tensor(s.astype(dtype), 1.0, 2.0, mode=mode) for s in stack])
            assert got.dtype == want.dtype and np.array_equal(got, want)
    with pytest.raises(InvalidParameter, match="images"):
        structure_tensor_stack(stack[0])
    with pytest.raises(InvalidParameter, match="sigma_w"):
        structure_tensor_stack(stack, 1.0, float("inf"))
