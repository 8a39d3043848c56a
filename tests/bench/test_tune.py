"""Grid search picks the parameters with the lowest error on the development drives."""

from posbench.predictor_tools.tuning import GRIDS, SCALE_GRID, grid_for, grid_search
from posbench.scenarios.synthetic import generate_drive


def test_grid_search_prefers_matching_fix_noise():
    # rtk fixes state 0.02 m: R = (scale * 0.02)^2, so scale 1 matches the noise, 150 (3 m) not
    drives = [generate_drive(seed=1001, route="turns", duration_s=40)]
    best, trials = grid_search(
        "kf", drives, "rtk", {"gps_sigma_scale": [1.0, 150.0], "jerk_psd": [32.0]}, workers=1
    )
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


def test_calibration_makes_95_percent_of_the_development_ellipses_cover():
    # the scale is fitted on these drives, so on them the 95 % ellipse must cover 95 % of the
    # scored queries, whatever the filter's own covariance said
    import numpy as np

    from posbench.aggregation.uncertainty import COV
    from posbench.config import RunConfig
    from posbench.metrics.calibration import coverage, mahalanobis_sq
    from posbench.predictor_tools.tuning import calibrate
    from posbench.replay.runner import run
    from posbench.scoring.schema import scored_mask

    drives = [generate_drive(seed=1002, route="turns", duration_s=60)]
    for name, params in (("kf", {"gps_sigma_scale": 3.0, "jerk_psd": 32.0}), ("cv", {})):
        k = calibrate(name, drives, "consumer", params, workers=1)
        assert np.isfinite(k) and k > 0
        cfg = RunConfig(
            predictors=(name,),
            gps_profile="consumer",
            predictor_options={name: {**params, "cov_scale": k}},
            use_tuned=False,
        )
        t = run(drives, cfg, workers=1)[0].traces
        t = t[scored_mask(t)]
        err = t[["x", "y"]].to_numpy(float) - t[["x_ref", "y_ref"]].to_numpy(float)
        cov95 = coverage(mahalanobis_sq(err, t[COV].to_numpy(float)), (0.95,))[0]
        assert abs(cov95 - 0.95) < 0.01, (name, k, cov95)


def test_calibration_of_a_predictor_without_covariance_is_nan():
    import math

    from posbench.predictor_tools.tuning import calibrate

    drives = [generate_drive(seed=1003, route="straight", duration_s=20)]
    assert math.isnan(calibrate("poly", drives, "rtk", {}, workers=1))


def test_a_tuning_the_run_refuses_is_not_saved(tmp_path):
    # the entry is checked with the run's own check before it replaces the file: a NaN
    # jerk density is refused in one line naming why, and the user's file stays as it was
    import json
    import math

    import pytest

    from posbench.errors import UsageError
    from posbench.predictor_tools.tuning import save_tuned
    from posbench.replay.predictor_setup import check_tuning_file

    out = tmp_path / "t.json"
    save_tuned("kf", "rtk", {"jerk_psd": 4.0}, "by hand", out)
    before = out.read_bytes()
    with pytest.raises(UsageError) as e:
        save_tuned("kf", "none", {"jerk_psd": math.nan}, "diverged", out)
    assert str(e.value).startswith(f"nothing saved to {out}: `bench run --tuning` would refuse")
    # the run's own check refuses it: a NaN is no number the option takes
    assert (
        "kf (none) cannot be created with its parameters: jerk_psd takes a number or null, not NaN"
        in str(e.value)
    )
    assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["t.json"]
    assert json.loads(before)["kf"]["rtk"]["params"] == {"jerk_psd": 4.0}
    check_tuning_file(out, ["kf"], {})  # what was kept is still a file the run takes


def test_a_stop_while_saving_leaves_the_tuning_file_whole(tmp_path, monkeypatch):
    # the merged file is written beside the user's, synced and renamed over it: a kill
    # before the rename (here: in the fsync) leaves the old file intact and no stray file
    import os

    import pytest

    from posbench.predictor_tools.tuning import save_tuned

    out = tmp_path / "t.json"
    save_tuned("kf", "rtk", {"jerk_psd": 4.0}, "by hand", out)
    before = out.read_bytes()
    synced: list[str] = []

    def killed(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", killed)
    with pytest.raises(KeyboardInterrupt):
        save_tuned("kf", "none", {"jerk_psd": 8.0}, "by hand", out)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.json"]
    assert synced and os.path.dirname(synced[0]) == str(tmp_path) and synced[0] != str(out)
