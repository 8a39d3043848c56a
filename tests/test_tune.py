"""Grid search picks the parameters with the lowest error on the development drives."""

from bench.tune import GRIDS, SCALE_GRID, grid_for, grid_search
from scenarios.synthetic import generate_drive


def test_grid_search_prefers_matching_fix_noise():
    # rtk fixes state 0.02 m: R = (scale * 0.02)^2, so scale 1 matches the noise, 150 (3 m) not
    drives = [generate_drive(seed=1001, route="turns", duration_s=40)]
    best, trials = grid_search("kf", drives, "rtk",
                               {"gps_sigma_scale": [1.0, 150.0], "jerk_psd": [32.0]}, workers=1)
    assert len(trials) == 2
    scores = {t[0]["gps_sigma_scale"]: t[1] for t in trials}
    assert best["gps_sigma_scale"] == 1.0 and scores[1.0] < scores[150.0]


def test_grid_tunes_the_scale_where_fixes_state_their_accuracy():
    for name in ("kf", "ekf"):
        for profile in ("rtk", "consumer"):
            g = grid_for(name, profile)
            assert "gps_sigma" not in g and g["gps_sigma_scale"] == SCALE_GRID
            assert list(g)[1:] == list(GRIDS[name])[1:]  # same order: the scale tuned jointly
        for profile in ("none", "native"):  # no stated accuracy: the constant R is tuned
            assert grid_for(name, profile) == GRIDS[name]
