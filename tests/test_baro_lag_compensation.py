"""The terrain filters take the barometer's lag out of the height their INS follows (`baro_lag_s`, which a
scenario sets to its sensors.baro.lag_tau_s): against the same flight read by a barometer without lag."""

import numpy as np
import pytest

from trn_env.sim.closed_loop import run_scenario


@pytest.mark.parametrize("navigator", ["pmf", "pf"])
def test_the_filters_follow_the_height_a_barometer_without_lag_gives(navigator):
    """90 s of the default route (climbs and descents of up to 8.7 m/s) flown three times with the same seed
    and draws: a barometer without lag; one with a 0.6 s lag, the navigator compensating (the scenario's
    default); the same lag left in (baro_lag_s = 0). With the compensation the navigator's height and
    position stay within centimetres of the lag-free run's; without it the height is metres off."""
    def fly(sets):
        return run_scenario("default", duration_s=90.0, navigator=navigator, pipeline=False, sets=sets).arrays

    clean = fly({"sensors.baro.lag_tau_s": 0.0})
    taken_out = fly({"sensors.baro.lag_tau_s": 0.6})
    left_in = fly({"sensors.baro.lag_tau_s": 0.6, "navigator.settings.baro_lag_s": 0.0})
    assert np.abs(clean["true_v_ned_mps"][:, 2]).max() > 5.0      # the flight climbs: the lag shows

    def off(run):
        dh = np.abs(run["est_h_m"] - clean["est_h_m"]).max()
        dn = np.abs(run["est_lat_rad"] - clean["est_lat_rad"]).max() * 6.37e6
        return dh, dn

    dh_out, dn_out = off(taken_out)
    dh_in, _ = off(left_in)
    assert dh_in > 2.0, dh_in
    assert dh_out < 0.2 and dn_out < 0.5, (dh_out, dn_out)
