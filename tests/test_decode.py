"""Decoding real GRIB2/NetCDF files: generated ones against the analytic fields, and JMA fixtures."""

import numpy as np
import pytest

from pipeline.decode.errors import DecodeError
from pipeline.decode.grib import list_fields
from pipeline.decode.jma import decode_gsm, decode_gwm
from pipeline.decode.oscar import decode_oscar
from pipeline.synthetic import weather
from pipeline.synthetic.grib_writer import jma_grid, write_gsm_file, write_gwm_file
from pipeline.synthetic.oscar_writer import write_oscar_v1, write_oscar_v2

CYCLE = np.datetime64("2020-12-01T12", "ns")


def _grid(res=0.5):
    lat, lon = jma_grid(res)
    return np.meshgrid(lat, lon, indexing="ij")


def _gsm(path, order=None, with_wind=True):
    L, O = _grid()
    u, v = weather.wind_uv(weather.hours_since_epoch(CYCLE) + 36, L, O)
    fields = {"prmsl": 101000.0 + 0 * u, "t2m": 280.0 + 0 * u}
    if with_wind:
        fields.update(u10=u, v10=v)
    write_gsm_file(path, CYCLE, 36, fields, order=order)
    return u, v


def test_gsm_selects_10m_wind_by_code_not_position(tmp_path):
    u, v = _gsm(tmp_path / "a.bin", order=["v10", "t2m", "u10", "prmsl"])
    ds = decode_gsm(tmp_path / "a.bin")
    assert int(ds.step) == 36 and ds.valid_time.values == CYCLE + np.timedelta64(36, "h")
    assert ds.lat.values[0] == -90 and np.all(np.diff(ds.lat.values) > 0)
    # point (35N, 140E) in the JMA grid: row (90-35)/0.5, col 140/0.5
    assert float(ds.u10.sel(lat=35, lon=140)) == pytest.approx(u[110, 280], abs=0.01)
    assert float(ds.v10.sel(lat=35, lon=140)) == pytest.approx(v[110, 280], abs=0.01)
    assert not list(tmp_path.glob("*.idx"))


def test_gsm_without_wind_names_the_file(tmp_path):
    _gsm(tmp_path / "nowind.bin", with_wind=False)
    with pytest.raises(DecodeError, match="nowind.bin.*10 m wind"):
        decode_gsm(tmp_path / "nowind.bin")


@pytest.mark.parametrize("land_as", ["bitmap", "fill"])
def test_gwm_land_becomes_nan(tmp_path, land_as):
    from tests import land_reference as globe

    L, O = _grid()
    land = globe.is_land(L, ((O + 180) % 360) - 180)
    t = weather.hours_since_epoch(CYCLE)
    swh, mwd, mwp = (np.stack(x) for x in zip(*(weather.waves(t + s, L, O) for s in (0, 6))))
    write_gwm_file(tmp_path / "g.bin", CYCLE, [0, 6], {"swh": swh, "mwd": mwd, "mwp": mwp}, land, land_as=land_as)
    ds = decode_gwm(tmp_path / "g.bin")
    assert list(ds.step.values) == [0, 6]
    assert np.isnan(float(ds.swh.sel(step=6, lat=36, lon=138.5)))  # central Japan is land
    assert float(ds.swh.sel(step=6, lat=30, lon=150)) == pytest.approx(swh[1, 120, 300], abs=0.01)
    assert float(ds.mwd.sel(step=0, lat=30, lon=150)) == pytest.approx(mwd[0, 120, 300], abs=0.05)


def test_gwm_quarter_degree_reads_its_own_grid(tmp_path):
    L, O = _grid(0.25)
    z = np.ones((1,) + L.shape)
    write_gwm_file(tmp_path / "q.bin", CYCLE, [0], {"swh": 2 * z, "mwd": 90 * z, "mwp": 8 * z}, np.zeros(L.shape, bool), res_deg=0.25)
    ds = decode_gwm(tmp_path / "q.bin")
    assert ds.sizes["lat"] == 721 and ds.sizes["lon"] == 1440
    assert float(ds.swh.sel(step=0, lat=10.25, lon=100.75)) == pytest.approx(2.0, abs=0.01)


@pytest.mark.parametrize("content", [b"", b"GRIB\x00\x00garbage" * 10, b"not a grib file at all"])
def test_garbage_grib_is_a_decode_error(tmp_path, content):
    p = tmp_path / "bad.bin"
    p.write_bytes(content)
    with pytest.raises(DecodeError, match="bad.bin"):
        decode_gsm(p)


def test_truncated_grib_is_a_decode_error(tmp_path):
    _gsm(tmp_path / "full.bin")
    data = (tmp_path / "full.bin").read_bytes()
    (tmp_path / "cut.bin").write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(DecodeError, match="cut.bin"):
        decode_gsm(tmp_path / "cut.bin")


def test_jma_fixtures_decode_every_field(jma_fixtures):
    meps = list_fields(next(jma_fixtures.glob("*MEPS*")))
    assert len(meps) == 20  # several fields per message, each seen
    assert {f.short_name for f in meps} >= {"u", "v", "t"}
    assert all(f.centre == 34 and (f.ni, f.nj) == (241, 253) for f in meps)
    msg = list_fields(next(jma_fixtures.glob("*MSG*")))
    assert sorted({f.step_h for f in msg}) == [3, 6, 9, 12, 15, 18, 21, 24]
    assert {f.short_name for f in msg} == {"unknown"}
    with pytest.raises(DecodeError, match="10 m wind"):
        decode_gsm(next(jma_fixtures.glob("*MEPS*")))


def _uv(t, la, lo):
    return weather.currents_uv(weather.hours_since_epoch(np.datetime64(t, "ns")), la, lo)


def test_oscar_v1_layout_is_fixed(tmp_path):
    p = write_oscar_v1(tmp_path / "oscar_vel10285.nc", [np.datetime64("2020-11-30", "ns")], _uv, res_deg=0.5)
    ds = decode_oscar(p)
    assert ds.sizes["lon"] == 720 and ds.lon.values.min() == 0 and ds.lon.values.max() == 359.5  # 20→420 folded, overlap dropped
    assert np.all(np.diff(ds.lat.values) > 0) and ds.lat.values[0] == -80
    assert ds.time.values[0] == np.datetime64("2020-11-30", "ns")
    assert set(ds.dims) == {"time", "lat", "lon"}
    expect = _uv(np.datetime64("2020-11-30"), 35.0, 140.0)[0]
    assert float(ds.uo.sel(lat=35, lon=140)[0]) == pytest.approx(expect, abs=1e-4)
    # lon 5E exists only in the repeated 380..420 band of the v1 file
    assert float(ds.uo.sel(lat=4, lon=5)[0]) == pytest.approx(_uv(np.datetime64("2020-11-30"), 4.0, 5.0)[0], abs=1e-4)


def test_oscar_v2_layout_is_fixed(tmp_path):
    p = write_oscar_v2(tmp_path / "oscar_currents_nrt_20201201.nc", np.datetime64("2020-12-01", "ns"), _uv, res_deg=0.5)
    ds = decode_oscar(p)
    assert set(ds.dims) == {"time", "lat", "lon"} and ds.uo.dims == ("time", "lat", "lon")
    assert ds.time.values[0] == np.datetime64("2020-12-01", "ns")
    assert np.isnan(float(ds.uo.sel(lat=36.25, lon=138.5, method="nearest")[0]))  # -999 over land → NaN
    lat = float(ds.lat.sel(lat=34.0, method="nearest"))
    assert float(ds.uo.sel(lat=lat, lon=140.0)[0]) == pytest.approx(_uv(np.datetime64("2020-12-01"), lat, 140.0)[0], abs=1e-4)


def test_oscar_with_unexpected_dims_is_a_decode_error(tmp_path):
    import netCDF4

    p = tmp_path / "odd.nc"
    with netCDF4.Dataset(p, "w") as nc:
        nc.createDimension("x", 3)
        nc.createVariable("u", "f4", ("x",))[:] = [1, 2, 3]
        nc.createVariable("v", "f4", ("x",))[:] = [1, 2, 3]
    with pytest.raises(DecodeError, match="odd.nc.*unexpected dimensions"):
        decode_oscar(p)


@pytest.mark.slow
def test_grib_files_decoded_in_threads_equal_a_serial_decode(tmp_path, jma_fixtures):
    """The ingest decodes GRIB2 files in worker threads: eccodes (built thread-safe, multi-field support on)
    must give every thread exactly what a serial decode gives, including JMA's multi-field messages."""
    from concurrent.futures import ThreadPoolExecutor

    from pipeline.synthetic.mirror import write_mirror

    write_mirror(tmp_path, "2020-12-01", "2020-12-01", cycles=(0,), max_lead_h=12, seed=0)  # 3 GSM leads, 1 GWM file
    files = sorted(tmp_path.rglob("*_grib2.bin"))
    assert [p.name.split("_")[5] for p in files] == ["GSM"] * 3 + ["GWM"]
    jobs = [(decode_gwm if "GWM" in p.name else decode_gsm, p) for p in files]
    jobs += [(list_fields, p) for p in sorted(jma_fixtures.glob("*grib2.bin*"))]
    serial = [fn(p) for fn, p in jobs]
    with ThreadPoolExecutor(4) as pool:
        for _ in range(2):
            threaded = list(pool.map(lambda job: job[0](job[1]), jobs))
            for (fn, p), a, b in zip(jobs, serial, threaded):
                assert (a == b) if fn is list_fields else a.identical(b), p.name
