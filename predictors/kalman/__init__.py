"""The Kalman filters: ``kf`` (linear, constant acceleration) and ``ekf`` (extended, CTRA),
each a bank of filters run as rows of one array by compiled kernels.

How a filter is composed (Stone Soup's split: a motion model, one update per sensor):

- **motion models**, pure maths written once: constant acceleration in
  :mod:`posbench.metrics.ca_model` (F, the white-jerk Q; the bound row uses the same),
  CTRA in :mod:`~posbench.predictors.kalman.ctra_model` (the step, its Jacobian, Q);
- **sensor inputs**, :mod:`~posbench.predictors.kalman.inputs`: one small option type per
  sensor (GNSS fixes, IMU acceleration, heading, wheel speed), with its defaults and
  ranges, and the flat ``--set`` names that address them; the helpers they need:
  :mod:`~posbench.predictors.kalman.gnss_noise` (a fix's white and slow noise, the
  fix-to-fix noise estimated in :mod:`~posbench.predictors.kalman.fix_noise`),
  :mod:`~posbench.predictors.kalman.course_heading` (heading from fix chords and the gyro),
  :mod:`~posbench.predictors.kalman.accel_bias` (the accelerometer's vehicle-frame bias);
- **rows**, the compiled predict and per-sensor updates of every member at once:
  :mod:`~posbench.predictors.kalman.ca_rows`, :mod:`~posbench.predictors.kalman.ctra_rows`
  (the kf's IMU sample, with its heading trackers and bias estimators, in
  :mod:`~posbench.predictors.kalman.ca_imu`);
- **banks**, :mod:`~posbench.predictors.kalman.row_bank` (selection by the likelihood of
  each member's fix predictions, shadows scored at longer horizons for outages) under
  :class:`~posbench.predictors.kalman.kf.KalmanBank` and
  :class:`~posbench.predictors.kalman.ekf.EkfBank`;
- **tuning**, :mod:`~posbench.predictors.kalman.tuning`: the kf's noise fitted by gradient.

The member-object filters (``LinearKalman``, ``CtraEkf``, ``ModelBank``) are the tests'
reference, in tests/reference_filters, checked in turn against filterpy.

Units: seconds, metres, radians, local ENU.
"""
