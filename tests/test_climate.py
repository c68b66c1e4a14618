"""Climate: extraterrestrial irradiation, Angstrom-Prescott, diffuse fraction, rain days, CSV."""
import numpy as np
import pytest

from mitsuba_veg.climate import (ClimateTable, daily_weather, diffuse_fraction_daily,
                                 extraterrestrial_irradiation, load_csv, rain_schedule)
from mitsuba_veg.errors import ParameterError


def test_extraterrestrial_irradiation_fao56_example_8():
    """FAO-56 example 8: 20 deg S, 3 September (J = 246): Ra = 32.2 MJ m-2 day-1 with
    Gsc = 0.0820 MJ m-2 min-1 (1366.7 W m-2); we use 1361 W m-2."""
    H0 = extraterrestrial_irradiation(-20.0, 246) / 1e6
    assert H0 * 1366.7 / 1361.0 == pytest.approx(32.2, abs=0.1)


def test_table_4_3_weather():
    t = ClimateTable()
    w = daily_weather(t, 35.0, 365 * 2, seed=4, start_day=1)
    assert np.all(w.T == 288.15) and np.all(w.rh == 0.73) and np.all(w.U == 0.2)
    assert np.all(w.A == 0.75)
    # rain: 180 rain days a year of 1861.2/180 mm each
    for y in range(2):
        p = w.P[y * 365:(y + 1) * 365]
        assert (p > 0).sum() == 180
        assert p.sum() == pytest.approx(1861.2)
    # Angstrom-Prescott: H = H0 (0.25 + 0.5 * 0.75)
    assert w.ghi[0] == pytest.approx(w.extra["H0_J_m2"][0] * 0.625 / 86400)
    assert np.allclose(w.beam + w.diffuse, w.ghi)
    # physically sensible at 35 N: winter ~120, summer ~270 W m-2 daily mean
    assert 100 < w.ghi[0] < 140 and 240 < w.ghi[172] < 300
    # reproducible from the seed, different for another seed
    assert np.array_equal(rain_schedule(365, 180, 4), rain_schedule(365, 180, 4))
    assert not np.array_equal(rain_schedule(365, 180, 4), rain_schedule(365, 180, 5))


def test_erbs_daily_diffuse_fraction():
    assert diffuse_fraction_daily(0.5) == pytest.approx(1.391 - 3.560 * .5 + 4.189 * .25
                                                        - 2.137 * .125)
    assert diffuse_fraction_daily(0.8) == pytest.approx(0.175)
    k = np.linspace(0.17, 0.71, 30)  # (clipped to 1 below K ~ 0.15)
    assert np.all(np.diff(diffuse_fraction_daily(k)) < 0)


def test_bad_climate_values_name_the_field():
    with pytest.raises(ParameterError, match=r"climate\.humidity = 1\.5.*\[0\.0, 1\.0\]"):
        ClimateTable(humidity=1.5)
    with pytest.raises(ParameterError, match="sunshine"):
        ClimateTable(sunshine=9.0, possible_sunshine=8.0)


def test_csv_series_and_nan_cell(tmp_path):
    good = tmp_path / "w.csv"
    good.write_text("T,rh,P,U,N,N0\n288,0.7,0,0.2,6,8\n290,0.8,12.5,0.3,2,8\n")
    w = load_csv(good, 35.0)
    assert w.T.tolist() == [288, 290] and w.P.tolist() == [0, 12.5]
    assert w.A.tolist() == [0.75, 0.25]
    assert w.ghi[1] < w.ghi[0]
    bad = tmp_path / "bad.csv"
    bad.write_text("T,rh,P\n288,0.7,0\n290,nan,1\n")
    with pytest.raises(ParameterError, match=r"bad\.csv row 3 column rh.*nan"):
        load_csv(bad, 35.0)
    # no P column: refused (no silent 'no rain'), naming the fix
    dry = tmp_path / "dry.csv"
    dry.write_text("T,rh\n288,0.7\n")
    with pytest.raises(ParameterError, match=r"dry\.csv columns.*a P column.*precipitation"):
        load_csv(dry, 35.0)
    # without a day_of_year column the days count from start_day (the run's start date)
    w = load_csv(good, 35.0, start_day=172)
    w1 = load_csv(good, 35.0)
    assert w.day_of_year.tolist() == [172, 173] and w1.day_of_year.tolist() == [1, 2]
    assert w.ghi[0] > 2 * w1.ghi[0]        # midsummer against 1 January at 35° N
    with pytest.raises(ParameterError, match="start_day"):
        load_csv(good, 35.0, start_day=0)


def test_one_declination_for_every_daily_formula():
    """FAO-56 eq 24 (FAO-56 example 8: 3 September, J = 246, delta = 0.120 rad) serves H0, the
    sunset angle, the world's noon sun and the render's seasons."""
    from mitsuba_veg.climate import solar_declination, sunset_hour_angle
    from mitsuba_veg.render.seasons import daily_extraterrestrial_mj
    assert float(solar_declination(246)) == pytest.approx(0.120, abs=5e-4)
    assert float(sunset_hour_angle(-20.0, 246)) == pytest.approx(1.527, abs=1e-3)
    # FAO-56 example 8: Ra = 32.2 MJ m-2 d-1 with Gsc = 1367 W m-2 (the package's is 1361)
    assert float(daily_extraterrestrial_mj(-20.0, 246)) == pytest.approx(32.2 * 1361 / 1367,
                                                                          abs=0.05)
    assert float(extraterrestrial_irradiation(-20.0, 246)) / 1e6 == pytest.approx(
        32.2 * 1361 / 1367, abs=0.05)
    # the world's noon sun at 20 S on 3 September: 90 - |-20 - 6.876| deg
    from mitsuba_veg.daily.inputs import noon_elevation
    assert float(noon_elevation(-20.0, 246)) == pytest.approx(90 - (20 + 6.876), abs=0.03)
