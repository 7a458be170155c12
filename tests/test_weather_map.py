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


def test_a_map_says_arrows_point_where_the_flow_goes_and_draws_none_on_land():
    from pipeline.export.weather_map import weather_map_figure
    from pipeline.routing.land_mask import is_sea

    lat, lon = np.arange(45.0, 24.9, -0.5), np.arange(125.0, 150.01, 0.5)  # Japan and its seas
    fig = weather_map_figure(lat, lon, _step(shape=(lat.size, lon.size)), "wind", "wind · valid 2020-12-01T12 UTC")
    ax = fig.axes[0]
    assert ax.get_title().splitlines() == ["wind · valid 2020-12-01T12 UTC",
                                           "arrows point where the wind blows TO (its coming-from direction + 180°)"]
    (arrows,) = [c for c in ax.collections if type(c).__name__ == "Quiver"]
    drawn = ~np.ma.getmaskarray(np.ma.array(arrows.U, mask=arrows.Umask))  # quiver keeps the mask apart
    xy = arrows.XY[drawn]
    assert len(xy) > 50 and is_sea(xy[:, 1], xy[:, 0]).all()
    assert (~drawn).sum() > 20  # Honshu, Kyushu, Korea: no arrows there


def test_a_box_across_the_antimeridian_is_drawn_in_one_piece():
    from pipeline.export.weather_map import weather_map_figure

    lat, lon = np.linspace(50.0, 30.0, 21), np.concatenate([np.arange(170.0, 180.0), np.arange(0.0, 11.0) - 180.0])
    ax = weather_map_figure(lat, lon, _step(shape=(lat.size, lon.size)), "waves", "waves").axes[0]
    x0, x1 = ax.get_xlim()
    assert (x0, x1) == pytest.approx((170.0, 190.0))  # 170°E .. 170°W, not −180 .. 180


def test_the_fleet_box_holds_every_port_with_a_margin_also_across_the_antimeridian():
    from flows.jobs.run_pictures import FLEET_MARGIN_DEG, fleet_box

    assert fleet_box([(35.0, 139.8), (13.4, 144.6), (22.5, 120.2)]) == pytest.approx(
        (13.4 - FLEET_MARGIN_DEG, 35.0 + FLEET_MARGIN_DEG, 120.2 - FLEET_MARGIN_DEG, 144.6 + FLEET_MARGIN_DEG))
    south, north, west, east = fleet_box([(50.0, 175.0), (52.0, -170.0), (None, 3.0)])
    assert (west, east) == pytest.approx((170.0, 195.0)) and (south, north) == pytest.approx((45.0, 57.0))
    assert fleet_box([]) is None
