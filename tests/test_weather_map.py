"""Weather maps: arrows point where wind, waves and water go; magnitudes in the units on the colour bar."""

from __future__ import annotations

import io

import numpy as np
import pytest

from pipeline.export.weather_map import animation_gif, magnitude_and_flow, weather_map_png
from pipeline.routing.geodesy import KN_PER_MS


def _step(u10=5.0, v10=0.0, swh=2.0, mwd=270.0, uo=0.0, vo=-0.5, shape=(9, 19)):
    return {k: np.full(shape, val) for k, val in dict(u10=u10, v10=v10, swh=swh, mwd=mwd, uo=uo, vo=vo).items()}


def test_magnitudes_and_flow_directions():
    s = _step()
    mag, u, v, label, _ = magnitude_and_flow(s, "wind")  # a westerly: from the west, blowing east
    assert mag[0, 0] == pytest.approx(5.0 * KN_PER_MS) and "[kn]" in label and u[0, 0] > 0 and v[0, 0] == 0
    mag, u, v, label, _ = magnitude_and_flow(s, "waves")  # waves from 270° travel east
    assert mag[0, 0] == 2.0 and "[m]" in label and u[0, 0] == pytest.approx(1.0) and v[0, 0] == pytest.approx(0.0, abs=1e-12)
    mag, u, v, label, _ = magnitude_and_flow(s, "currents")  # going-to: southward
    assert mag[0, 0] == pytest.approx(0.5 * KN_PER_MS) and v[0, 0] < 0
    with pytest.raises(ValueError, match="use one of wind, waves, currents"):
        magnitude_and_flow(s, "rain")


def test_a_map_and_an_animation_are_real_images():
    from PIL import Image

    lat, lon = np.linspace(40.0, 20.0, 9), np.arange(130.0, 149.0, 1.0)  # north to south, 0..360 longitudes
    frames = [weather_map_png(lat, lon, _step(swh=h), "waves", f"frame {h}") for h in (1.0, 3.0)]
    assert all(f[:8] == b"\x89PNG\r\n\x1a\n" for f in frames)
    gif = animation_gif(frames, frame_ms=100)
    img = Image.open(io.BytesIO(gif))
    assert gif[:6] == b"GIF89a" and img.n_frames == 2
