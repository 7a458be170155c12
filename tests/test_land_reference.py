"""The tests' land reference (tests/land_reference.py) answers as the `global-land-mask` package itself."""

import numpy as np
import pytest

from tests import land_reference


@pytest.mark.slow  # imports the package, which decompresses its whole 933 MB grid
def test_the_land_reference_answers_as_the_package():
    from global_land_mask import globe

    rng = np.random.default_rng(7)
    lat, lon = rng.uniform(-90, 90, 200_000), rng.uniform(-180, 180, 200_000)
    edges = np.array([-90.0, -89.999, 0.0, 89.999, 90.0]), np.array([-180.0, -179.999, 0.0, 179.999, 180.0])
    lat, lon = np.concatenate([lat, np.repeat(edges[0], 5)]), np.concatenate([lon, np.tile(edges[1], 5)])
    assert np.array_equal(land_reference.is_ocean(lat, lon), globe.is_ocean(lat, lon))
    assert np.array_equal(land_reference.is_land(lat, lon), globe.is_land(lat, lon))
    assert 0.2 < land_reference.is_land(lat, lon).mean() < 0.4  # the earth's land share: the bits are not all one kind
    for a, b in [(90, 180), (-90, -180), (36, 138), (0, 0), (51.5, -0.1)]:  # integer and scalar inputs too
        assert land_reference.is_land(a, b) == globe.is_land(a, b)
    rows, cols = np.arange(7000, 7300), np.arange(43000, 43500) % 43200
    assert np.array_equal(land_reference.ocean_cells(rows, cols), globe._mask[np.ix_(rows, cols)])
    with pytest.raises(ValueError, match="latitude"):
        land_reference.is_ocean(91.0, 0.0)
    with pytest.raises(ValueError, match="longitude"):
        land_reference.is_ocean(0.0, -181.0)


def test_the_land_reference_knows_land_from_sea():
    assert land_reference.is_land(36.0, 138.0) and land_reference.is_land(48.85, 2.35)  # central Japan, Paris
    assert land_reference.is_ocean(0.0, -140.0) and land_reference.is_ocean(-40.0, 60.0)  # Pacific, Indian Ocean
    assert land_reference.is_ocean([0.0, 36.0], [-140.0, 138.0]).tolist() == [True, False]
