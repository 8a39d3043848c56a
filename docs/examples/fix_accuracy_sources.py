"""Print the fix accuracy (per-axis 1-sigma [m]) each source in ../shared/data states.

Run from the repository root: python docs/examples/fix_accuracy_sources.py
"""

import numpy as np

from posbench.scenarios.degrade import degrade_gps
from posbench.scenarios.loaders import load
from posbench.scenarios.synthetic import default_drives

d = default_drives()[0]
rows = [
    (x.name, x.meta.format, x.gps.accuracy)
    for x in load("../shared/data/kitti_raw/2011_09_26/2011_09_26_drive_0001_sync")
    + load("../shared/data/comma2k19")
    + load("../shared/data/aslan/aslan-20220408124005.pickle")
]
rows += [(d.name, "synthetic own", d.gps.accuracy)]
rows += [
    (d.name, f"degraded {p}", degrade_gps(d.truth, p, seed=0).accuracy)
    for p in ("none", "rtk", "consumer")
]
for name, fmt, a in rows:
    print(
        f"{name[:28]:28s} {fmt:18s}",
        "none stated"
        if a is None
        else f"per-axis 1-sigma median {np.nanmedian(a):.3f} m "
        f"({np.isfinite(a).sum()} of {a.size} fixes)",
    )
