"""``hybrid``: the tuned linear Kalman filter ``kf`` as a physics prior plus a learned
correction of its 0.2-0.8 s answers (ONNX at run time; torch only in ``model``/``export``)."""
