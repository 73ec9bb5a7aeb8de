"""Known-answer laminar volumes (texsynth.synth.io.laminar) and the spectral period
(texsynth.synth.analysis.spectrum)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from texsynth.synth.analysis.spectrum import dominant_period, radial_power_spectrum
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.io.laminar import onion_volume, turbostratic_volume
from texsynth.synth.io.patterns import grating


@pytest.mark.parametrize(
    ("shape", "angle", "period"), [((64, 64), 0.3, 6.0), ((100, 100), 0.0, 5.0), ((128, 96), 1.0, 7.3)]
)
def test_dominant_period_of_a_grating(shape: tuple[int, int], angle: float, period: float) -> None:
    assert dominant_period(grating(shape, angle, period=period)) == pytest.approx(period, rel=0.02)


def test_radial_spectrum_peaks_at_the_grating_frequency() -> None:
    freqs, power = radial_power_spectrum(grating((64, 64), 0.7, period=8.0))
    assert freqs[int(np.argmax(power))] == pytest.approx(1 / 8, abs=1 / 64)


def test_dominant_period_rejects_flat_and_small_inputs() -> None:
    with pytest.raises(InvalidInput, match="flat"):
        dominant_period(np.zeros((32, 32)))
    with pytest.raises(InvalidInput, match="every side >= 8"):
        dominant_period(np.zeros((4, 32)))
    with pytest.raises(InvalidInput, match="NaN"):
        dominant_period(np.full((16, 16), np.nan))


@pytest.mark.parametrize("period", [5.0, 6.0, 8.0])
def test_onion_period_matches_the_parameter(period: float) -> None:
    # large onions: the volume's spectrum is a sharp shell at 1 / period; the default density (cells about
    # 15 voxels in radius) reads 3-8% long (the cells' boundaries and small shells add low frequencies)
    for seed in (0, 1):
        vol = onion_volume((64, 64, 64), period=period, centres=2, seed=seed)
        assert dominant_period(vol) == pytest.approx(period, rel=0.04)
        assert dominant_period(onion_volume((64, 64, 64), period=period, seed=seed)) == pytest.approx(
            period, rel=0.1
        )


@pytest.mark.parametrize("period", [5.0, 6.0, 8.0])
@pytest.mark.parametrize("normal", [(1.0, 1.0, 1.0), (1.0, 0.0, 0.0)])
def test_turbostratic_period_matches_the_parameter(period: float, normal: tuple[float, float, float]) -> None:
    # crumpled sheets: the local spacing is period / |grad phi| with |grad phi| = 1 +- crumple (0.2), and a
    # 96^3 volume holds only a few crumples: seeds 0-2 measured within 0.94-1.12 of the period
    for seed in (0, 1, 2):
        vol = turbostratic_volume((96, 96, 96), period=period, normal=normal, seed=seed)
        assert dominant_period(vol) == pytest.approx(period, rel=0.13)
    flat = turbostratic_volume((64, 64, 64), period=period, normal=normal, crumple=0.0, noise=0.0)
    assert dominant_period(flat) == pytest.approx(period, rel=0.03)


def test_oblique_cut_widens_the_fringes() -> None:
    # sheets normal to (1, 1, 1): each plane sees fringes period / |(n_y, n_x)| = period * sqrt(3 / 2) apart
    vol = turbostratic_volume((96, 96, 96), period=6.0, crumple=0.0, noise=0.0, blur=0.0)
    for image in (vol[48], vol[:, 48], vol[:, :, 48]):
        assert dominant_period(image) == pytest.approx(6.0 * np.sqrt(1.5), rel=0.05)


@pytest.mark.parametrize("make", [onion_volume, turbostratic_volume])
def test_shapes_dtype_range_and_determinism(make) -> None:
    vol = make((16, 24, 40), seed=3)
    assert vol.shape == (16, 24, 40) and vol.dtype == np.float32
    assert vol.flags.c_contiguous and vol.min() >= 0.0 and vol.max() <= 1.0 and vol.std() > 0.05
    assert make((16, 24, 40), seed=3).tobytes() == vol.tobytes()
    assert make((16, 24, 40), seed=4).tobytes() != vol.tobytes()


def test_onion_grey_is_the_cosine_of_the_distance_to_its_centre() -> None:
    # one onion, no noise nor blur: grey = 0.5 + 0.5 cos(2 pi d / period) around one point, which a
    # least-squares fit of the shells finds again (the centre drawn from the seed is not assumed)
    vol = onion_volume((24, 24, 24), period=6.0, centres=1, blur=0.0, noise=0.0, seed=2).astype(np.float64)
    zz, yy, xx = np.mgrid[0:24, 0:24, 0:24].astype(np.float64)
    cos_d = 2.0 * vol - 1.0

    def misfit(c: np.ndarray) -> float:
        d = np.sqrt((zz - c[0]) ** 2 + (yy - c[1]) ** 2 + (xx - c[2]) ** 2)
        return float(np.mean((np.cos(2 * np.pi * d / 6.0) - cos_d) ** 2))

    starts = [np.array(c, dtype=np.float64) for c in np.ndindex(6, 6, 6)]
    start = min((c * 4.0 + 2.0 for c in starts), key=misfit)
    fit = optimize.minimize(misfit, start, method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-9})
    best = (fit.fun, fit.x)
    assert best[0] < 1e-6
    assert vol.min() >= 0.0 and vol.max() <= 1.0 and vol.max() - vol.min() > 0.99


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"shape": (4, 16, 16)}, "shape"),
        ({"shape": (16, 16)}, "shape"),
        ({"shape": "abc"}, "shape"),
        ({"shape": (16, 16, 16), "period": 2.0}, "period"),
        ({"shape": (16, 16, 16), "period": float("nan")}, "period"),
        ({"shape": (16, 16, 16), "blur": -1.0}, "blur"),
        ({"shape": (16, 16, 16), "noise": -0.1}, "noise"),
    ],
)
@pytest.mark.parametrize("make", [onion_volume, turbostratic_volume])
def test_bad_inputs_name_the_field(make, kwargs: dict, name: str) -> None:
    with pytest.raises(InvalidParameter, match=f"'{name}'"):
        make(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"centres": 0}, "centres"),
        ({"centres": 2.5}, "centres"),
    ],
)
def test_onion_bad_centres(kwargs: dict, name: str) -> None:
    with pytest.raises(InvalidParameter, match=f"'{name}'"):
        onion_volume((16, 16, 16), **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"normal": (0.0, 0.0, 0.0)}, "normal"),
        ({"normal": (1.0, 0.0)}, "normal"),
        ({"crumple": 0.9}, "crumple"),
        ({"correlation": 0.5}, "correlation"),
    ],
)
def test_turbostratic_bad_parameters(kwargs: dict, name: str) -> None:
    with pytest.raises(InvalidParameter, match=f"'{name}'"):
        turbostratic_volume((16, 16, 16), **kwargs)
