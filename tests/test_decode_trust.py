"""Decoded weather is physically plausible and what its file name promises, or the file is refused (`corrupt`)
with the reason: real GRIB2 written with eccodes and real NetCDF, each attack against its decoder."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.decode.errors import DecodeError
from pipeline.decode.jma import decode_gsm, decode_gwm
from pipeline.decode.oscar import decode_oscar
from pipeline.synthetic import weather
from pipeline.synthetic.grib_writer import jma_grid, write_gsm_file, write_gwm_file
from pipeline.synthetic.mirror import gsm_name
from pipeline.synthetic.oscar_writer import write_oscar_v2

CYCLE = np.datetime64("2020-12-01T00", "ns")
LEAD = 36


def _wind(lead_h=LEAD, lat_span=(90.0, -90.0)):
    lat = np.linspace(lat_span[0], lat_span[1], int(round(abs(lat_span[1] - lat_span[0]) / 0.5)) + 1)
    L, O = np.meshgrid(lat, jma_grid(0.5)[1], indexing="ij")
    return weather.wind_uv(weather.hours_since_epoch(CYCLE) + lead_h, L, O)


def _gsm_path(tmp_path, lead_h=LEAD):
    return tmp_path / gsm_name(CYCLE, lead_h)


def test_a_good_gsm_file_decodes(tmp_path):
    u, v = _wind()
    path = write_gsm_file(_gsm_path(tmp_path), CYCLE, LEAD, {"u10": u, "v10": v})
    ds = decode_gsm(path)
    assert float(ds.u10.sel(lat=35, lon=140)) == pytest.approx(u[110, 280], abs=0.01)
    assert float(np.abs(u).max()) > 20.0  # the storm: the km/h version below exceeds any real wind


def test_wind_in_km_per_h_is_refused(tmp_path):
    u, v = _wind()
    path = write_gsm_file(_gsm_path(tmp_path), CYCLE, LEAD, {"u10": 3.6 * u, "v10": 3.6 * v})
    with pytest.raises(DecodeError, match=r"of u10 outside the plausible -75\.\.75 m s-1 .*wrong units"):
        decode_gsm(path)


def test_non_finite_wind_is_a_hole_and_refused_never_calm(tmp_path):
    u, v = _wind()
    lat, lon = jma_grid(0.5)
    box = np.ix_((lat >= 10) & (lat <= 36), (lon >= 135) & (lon <= 150))
    u[box], v[box] = np.inf, np.nan
    path = write_gsm_file(_gsm_path(tmp_path), CYCLE, LEAD, {"u10": u, "v10": v}, packing="grid_ieee")
    with pytest.raises(DecodeError, match=r"missing or non-finite value\(s\) of u10 \(lat 10\.\.36, lon 135\.\.150\)"):
        decode_gsm(path)


def test_a_file_of_another_date_under_this_name_is_refused(tmp_path):
    u, v = _wind()
    path = write_gsm_file(_gsm_path(tmp_path), np.datetime64("2019-01-01T00", "ns"), LEAD, {"u10": u, "v10": v})
    with pytest.raises(DecodeError, match="reference time 2019-01-01T00:00 in the file, 2020-12-01T00:00 in its name"):
        decode_gsm(path)


def test_a_lead_other_than_the_name_s_is_refused(tmp_path):
    u, v = _wind(LEAD + 6)
    path = write_gsm_file(_gsm_path(tmp_path), CYCLE, LEAD + 6, {"u10": u, "v10": v})
    with pytest.raises(DecodeError, match="lead 42 h in the file, 36..36 h in its name"):
        decode_gsm(path)


def test_a_regional_grid_is_refused(tmp_path):
    u, v = _wind(lat_span=(60.0, 0.0))
    path = write_gsm_file(_gsm_path(tmp_path), CYCLE, LEAD, {"u10": u, "v10": v}, lat_span=(60.0, 0.0))
    with pytest.raises(DecodeError, match="wrong grid: latitudes 0..60, expected a global grid covering -90..90"):
        decode_gsm(path)


def test_a_south_to_north_field_is_turned_not_mirrored(tmp_path):
    u, v = _wind()
    north_first = write_gsm_file(tmp_path / "u.bin", CYCLE, LEAD, {"u10": u})
    south_first = write_gsm_file(tmp_path / "v.bin", CYCLE, LEAD, {"v10": v[::-1]}, lat_span=(-90.0, 90.0))
    path = _gsm_path(tmp_path)
    path.write_bytes(north_first.read_bytes() + south_first.read_bytes())
    ds = decode_gsm(path)
    assert float(ds.v10.sel(lat=35, lon=140)) == pytest.approx(v[110, 280], abs=0.01)
    assert float(ds.v10.sel(lat=-35, lon=140)) == pytest.approx(v[250, 280], abs=0.01)
    assert v[110, 280] != pytest.approx(v[250, 280], abs=0.1)  # mirrored would have swapped them


def test_a_second_message_of_one_variable_and_lead_is_refused(tmp_path):
    u, v = _wind()
    first = write_gsm_file(tmp_path / "a.bin", CYCLE, LEAD, {"u10": u, "v10": v})
    extra = write_gsm_file(tmp_path / "b.bin", CYCLE, LEAD, {"u10": u + 40.0})
    path = _gsm_path(tmp_path)
    path.write_bytes(first.read_bytes() + extra.read_bytes())
    with pytest.raises(DecodeError, match="two u10 fields at lead 36 h"):
        decode_gsm(path)


def test_a_huge_declared_grid_is_refused_before_its_values_are_decoded(tmp_path):
    res = 0.1  # 3600×1801 = 6.5 M points declared by a file of a few kB (a constant field packs to nothing)
    lat, lon = jma_grid(res)
    const = np.full((lat.size, lon.size), 5.0)
    path = write_gsm_file(_gsm_path(tmp_path), CYCLE, LEAD, {"u10": const, "v10": const}, res_deg=res)
    assert path.stat().st_size < 10_000
    with pytest.raises(DecodeError, match=r"wrong grid: 3600×1801 points declared \(at most 1038240 expected\); not decoded"):
        decode_gsm(path)


def _gwm(tmp_path, name, steps, **change):
    lat, lon = jma_grid(0.5)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    t = weather.hours_since_epoch(CYCLE)
    swh, mwd, mwp = (np.stack(x) for x in zip(*(weather.waves(t + s, L, O) for s in steps)))
    fields = {"swh": swh, "mwd": mwd, "mwp": mwp} | change
    return write_gwm_file(tmp_path / name, CYCLE, steps, fields, np.zeros(L.shape, bool))


GWM_NAME = "Z__C_RJTD_20201201000000_GWM_GPV_Rgl_Gll0p5deg_FD0000-0012_grib2.bin"


def test_waves_of_a_lead_outside_the_name_s_range_are_refused(tmp_path):
    path = _gwm(tmp_path, GWM_NAME, [0, 6, 18])
    with pytest.raises(DecodeError, match="lead 18 h in the file, 0..12 h in its name"):
        decode_gwm(path)


def test_wave_heights_beyond_the_plausible_are_refused(tmp_path):
    path = _gwm(tmp_path, GWM_NAME, [0, 6], swh=np.full((2, 361, 720), 45.0))
    with pytest.raises(DecodeError, match=r"of swh outside the plausible 0\.\.30 m"):
        decode_gwm(path)


def test_a_wave_file_at_another_resolution_than_its_name_is_refused(tmp_path):
    path = _gwm(tmp_path, GWM_NAME.replace("0p5deg", "0p25deg"), [0, 6])
    with pytest.raises(DecodeError, match="spacing 0.5°×0.5°, expected 0.25° as the file name says"):
        decode_gwm(path)


def _uv(t, L, O):
    return 0.5 * np.cos(np.radians(L)), 0.2 * np.sin(np.radians(O))


def _oscar_in(tmp_path, units, scale):
    import netCDF4

    path = write_oscar_v2(tmp_path / "oscar_currents_nrt_20201201.nc", np.datetime64("2020-12-01", "ns"),
                          lambda t, L, O: tuple(scale * x for x in _uv(t, L, O)), res_deg=0.5)
    with netCDF4.Dataset(path, "a") as nc:
        for name in ("u", "v"):
            nc[name].units = units
    return path


def test_currents_in_cm_per_s_are_converted_from_their_units(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    m_s = decode_oscar(_oscar_in(tmp_path / "a", "m/s", 1.0))
    cm_s = decode_oscar(_oscar_in(tmp_path / "b", "cm/s", 100.0))
    assert float(np.nanmax(np.abs(cm_s.uo.values))) == pytest.approx(0.5, abs=1e-3)
    np.testing.assert_allclose(cm_s.uo.values, m_s.uo.values, atol=1e-5)
    np.testing.assert_allclose(cm_s.vo.values, m_s.vo.values, atol=1e-5)


def test_currents_in_cm_per_s_labelled_m_per_s_are_refused(tmp_path):
    path = _oscar_in(tmp_path, "m/s", 100.0)
    with pytest.raises(DecodeError, match=r"of uo outside the plausible -10\.\.10 m s-1"):
        decode_oscar(path)


def test_currents_in_unknown_units_are_refused(tmp_path):
    path = _oscar_in(tmp_path, "knots", 1.0)
    with pytest.raises(DecodeError, match="u is in 'knots', expected a speed"):
        decode_oscar(path)


def test_an_oscar_file_in_a_360_day_calendar_is_refused_naming_the_calendar(tmp_path):
    import netCDF4

    path = tmp_path / "oscar_currents_nrt_20201201.nc"
    with netCDF4.Dataset(path, "w") as nc:
        for name, n in (("time", 1), ("latitude", 3), ("longitude", 4)):
            nc.createDimension(name, n)
        t = nc.createVariable("time", "f8", ("time",))
        t.units, t.calendar = "days since 1990-01-01", "360_day"
        t[:] = [11000.0]
        nc.createVariable("latitude", "f4", ("latitude",))[:] = [-1.0, 0.0, 1.0]
        nc.createVariable("longitude", "f4", ("longitude",))[:] = [0.0, 90.0, 180.0, 270.0]
        for name in ("u", "v"):
            var = nc.createVariable(name, "f4", ("time", "latitude", "longitude"))
            var.units = "m/s"
            var[:] = np.full((1, 3, 4), 0.3)
    with pytest.raises(DecodeError, match="time axis in the '360_day' calendar, not the standard calendar"):
        decode_oscar(path)


@pytest.mark.slow
def test_a_redirect_to_a_file_url_is_refused_naming_the_scheme(tmp_path):
    from pipeline.sources.fetch import FetchOptions, fetch
    from tests.http_mirror import serve

    (tmp_path / "f.nc").write_bytes(b"x")
    with serve(tmp_path, {"f.nc": "redirect:file:///etc/passwd"}) as (url, handler):
        result = fetch(url + "f.nc", tmp_path / "out" / "f.nc", FetchOptions(retries=0))
    assert result.status in ("error", "missing") and not (tmp_path / "out" / "f.nc").exists()
    assert "redirect to a file: URL refused (only http and https redirects are followed" in result.error
    assert "None" not in result.error
