"""Grid search picks the parameters with the lowest error on the development drives."""

from bench.tune import grid_search
from scenarios.synthetic import generate_drive


def test_grid_search_prefers_matching_fix_noise():
    drives = [generate_drive(seed=1001, route="turns", duration_s=40)]
    best, trials = grid_search("kf", drives, "rtk", {"gps_sigma": [0.02, 3.0], "jerk_psd": [32.0]},
                               workers=1)
    assert len(trials) == 2
    scores = {t[0]["gps_sigma"]: t[1] for t in trials}
    assert best["gps_sigma"] == 0.02 and scores[0.02] < scores[3.0]
