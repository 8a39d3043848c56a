"""The checks of the position streams: ``gps`` (the fixes' scatter against the accuracy they
state, and how far they sit from a truth) and ``truth`` (GPS vs truth, judged relative to the
accuracy the fixes state). Positions in the drive's local metres (ENU), accuracies per-axis
1-sigma [m], angles in degrees in the figures."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from posbench.scenarios.align import similarity_2d
from posbench.scenarios.consistency_model import (
    FAIL,
    NA,
    PASS,
    TOLERANCES,
    WARN,
    Check,
    Tolerances,
    na,
)
from posbench.scenarios.consistency_motion import no_reference
from posbench.scenarios.consistency_stats import fix_scatter
from posbench.scenarios.drive import Drive
from posbench.scenarios.grid import interp_gapped
from posbench.scenarios.text import fixed
from posbench.scenarios.truth_gaps import truth_gap_note

#: fixes within this of the truth at every fix [m] are the truth's own samples (one source)
ONE_SOURCE_M = 1e-3


@dataclass
class GpsVsTruth:
    """The fixes against the truth at the fix times: ``figures`` (offset_m = |mean(gps -
    truth)|, rms_m, fixes, stated_m = the median combined per-axis 1-sigma both state
    (NaN when neither does), the similarity fit's scale, rotation_deg and fit_rms_m where
    the track is long enough); ``tests`` (name, value, warn limit, fail limit, unit), the
    limits widened by what the stated accuracy explains; ``one_source`` when the fixes
    are the truth's own samples."""

    figures: dict[str, float]
    tests: list[tuple[str, float, float, float, str]] = field(default_factory=list)
    one_source: bool = False

    def verdict(self) -> tuple[str, str]:
        """(verdict, the test that decided it with its limit), ``pass`` with ''."""
        for v, i in ((FAIL, 3), (WARN, 2)):
            for name, value, *lim, unit in self.tests:
                limit = lim[i - 2]
                if value > limit:
                    return v, f"{name} {value:.3g}{unit} (limit {limit:.3g}{unit})"
        return PASS, ""


def gps_vs_truth(drive: Drive, tol: Tolerances = TOLERANCES) -> GpsVsTruth | str:
    """:class:`GpsVsTruth` of a drive with a truth and fixes, or why there is none."""
    tr, g = drive.truth, drive.gps
    if tr is None or len(tr) < 2:
        return "no truth"
    if len(g) < 4:
        return no_reference(drive, tol)
    tx = interp_gapped(tr.t, tr.x, g.t, tol.max_fix_gap_s)
    ty = interp_gapped(tr.t, tr.y, g.t, tol.max_fix_gap_s)
    ok = np.isfinite(tx) & np.isfinite(ty)
    if ok.sum() < 4:
        return "GPS and truth do not overlap in time"
    src = np.column_stack([tx[ok], ty[ok]])
    d = np.column_stack([g.x[ok], g.y[ok]]) - src
    off = float(np.hypot(*d.mean(0)))
    rms = float(np.sqrt((d**2).sum(1).mean()))
    sigma = _stated_sigma(drive, ok)
    fig = {"offset_m": off, "rms_m": rms, "fixes": float(ok.sum()), "stated_m": sigma}
    if float(np.max(np.hypot(*d.T))) < ONE_SOURCE_M:
        return GpsVsTruth(fig, one_source=True)
    h = np.sqrt(2) * sigma if np.isfinite(sigma) else 0.0
    tests = [
        (
            "offset",
            off,
            max(tol.gps_truth_offset_warn_m, tol.gps_truth_sigma_warn * h),
            max(tol.gps_truth_offset_fail_m, tol.gps_truth_sigma_fail * h),
            " m",
        ),
        (
            "RMS",
            rms,
            max(tol.gps_truth_rms_warn_m, tol.gps_truth_sigma_warn * h),
            max(tol.gps_truth_rms_fail_m, tol.gps_truth_sigma_fail * h),
            " m",
        ),
    ]
    extent = float(np.sqrt(((src - src.mean(0)) ** 2).sum(1).mean()))
    if extent >= tol.min_extent_m:
        sc, rot, _, res = similarity_2d(src, src + d)
        fig.update(scale=sc, rotation_deg=float(np.degrees(rot)), fit_rms_m=res)
        explained = tol.fit_explained_k * h / extent  # [rad] and [-]
        tests += [
            (
                "rotation",
                abs(fig["rotation_deg"]),
                tol.rot_warn_deg + np.degrees(explained),
                tol.rot_fail_deg + np.degrees(explained),
                " deg",
            ),
            (
                "scale error",
                abs(sc - 1),
                tol.truth_scale_warn + explained,
                tol.truth_scale_fail + explained,
                "",
            ),
        ]
    return GpsVsTruth(fig, tests)


def _stated_sigma(drive: Drive, ok: np.ndarray) -> float:
    """Median over the compared fixes of the combined per-axis 1-sigma [m] the fixes and
    the truth state, sqrt(acc_gps^2 + acc_truth^2) (a missing one counts 0); NaN when
    neither states one."""
    g, tr = drive.gps, drive.truth
    n = int(ok.sum())
    a_g = g.accuracy[ok] if g.accuracy is not None else np.full(n, np.nan)
    a_t = np.full(n, np.nan)
    if tr is not None and tr.accuracy is not None and np.isfinite(tr.accuracy).sum() >= 2:
        fin = np.isfinite(tr.accuracy)
        a_t = np.interp(g.t[ok], tr.t[fin], tr.accuracy[fin])
    have = np.isfinite(a_g) | np.isfinite(a_t)
    if not have.any():
        return float("nan")
    comb = np.hypot(np.nan_to_num(a_g[have]), np.nan_to_num(a_t[have]))
    return float(np.median(comb))


def check_truth(
    drive: Drive, tol: Tolerances = TOLERANCES, cmp: GpsVsTruth | str | None = None
) -> Check:
    """GPS fixes against the truth at the same times [m]: mean offset, RMS and the
    similarity fit truth -> GPS (scale, rotation [deg], residual RMS), each judged against
    what the accuracy the fixes (and truth) state explains (:class:`GpsVsTruth`; absolute
    limits when none is stated). Fixes that are the truth's own samples pass; a truth
    stating a median accuracy worse than :attr:`Tolerances.max_fix_accuracy_m` warns (it is
    then no reference for the other streams); so does a truth sampled too sparsely for a
    reference position over a material part of its span
    (:func:`~posbench.scenarios.truth_gaps.truth_gap_note`), with its figures: its line
    first, then what the comparison found."""
    check = _check_truth(drive, tol, cmp)
    gaps = truth_gap_note(drive.truth.t) if drive.truth is not None else ""
    if not gaps or check.verdict == FAIL:
        return check
    found = f"; {check.reason}" if check.verdict != NA and check.reason else ""
    return Check(check.stream, WARN, gaps + found, check.figures)


def _check_truth(drive: Drive, tol: Tolerances, cmp: GpsVsTruth | str | None) -> Check:
    """:func:`check_truth` but its sampling."""
    s = "truth"
    cmp = gps_vs_truth(drive, tol) if cmp is None else cmp
    if isinstance(cmp, str):
        return na(s, cmp)
    fig = cmp.figures
    own = drive.truth_median_accuracy_m
    if own is not None and own > tol.max_fix_accuracy_m:
        fig = {**fig, "truth_stated_m": own}
        return Check(
            s,
            WARN,
            f"the truth states a median accuracy of {fixed(own, 1)} m > "
            f"{tol.max_fix_accuracy_m:g} m: no reference for the other "
            "streams",
            fig,
        )
    if cmp.one_source:
        return Check(s, PASS, "GPS fixes are the truth's own samples (one source)", fig)
    verdict, why = cmp.verdict()
    if verdict != PASS:
        return Check(s, verdict, f"GPS vs truth {why}{_stated(fig)}", fig)
    return Check(
        s,
        PASS,
        f"offset {fixed(fig['offset_m'], 2)} m, RMS {fixed(fig['rms_m'], 2)} m{_stated(fig)}",
        fig,
    )


def _stated(fig: dict[str, float]) -> str:
    sig = fig.get("stated_m", float("nan"))
    return f", stated accuracy {sig:.2g} m" if np.isfinite(sig) else ", no accuracy stated"


def _poor_receiver(cmp: GpsVsTruth | str, tol: Tolerances) -> str:
    """Why the fixes are a poor receiver by the truth ("" when they are not, when there is
    no truth, or when the truth itself fails): farther from it than the absolute warn
    limits, yet within what their stated accuracy explains."""
    if isinstance(cmp, str) or cmp.one_source or cmp.verdict()[0] == FAIL:
        return ""
    f = cmp.figures
    if f["offset_m"] > tol.gps_truth_offset_warn_m or f["rms_m"] > tol.gps_truth_rms_warn_m:
        return f"fixes {fixed(f['offset_m'], 1)} m from the truth (RMS {fixed(f['rms_m'], 1)} m)"
    return ""


def check_gps(
    drive: Drive, tol: Tolerances = TOLERANCES, cmp: GpsVsTruth | str | None = None
) -> Check:
    """Scatter of the fixes [m] (:func:`fix_scatter`) against the median accuracy the
    source states [m]; with a truth, also how far the fixes sit from it: a receiver beyond
    :attr:`Tolerances.gps_truth_offset_warn_m` (or the RMS one) that its stated accuracy
    explains is a poor receiver, a warning here (the truth is not to blame)."""
    s = "gps"
    g = drive.gps
    if len(g) < 4:
        return na(s, no_reference(drive, tol))
    cmp = gps_vs_truth(drive, tol) if cmp is None else cmp
    one_source = not isinstance(cmp, str) and cmp.one_source
    scatter = fix_scatter(g.t, g.x, g.y)
    fig = {"scatter_m": scatter, "fixes": float(len(g))}
    if not isinstance(cmp, str) and not one_source:
        fig.update(truth_offset_m=cmp.figures["offset_m"], truth_rms_m=cmp.figures["rms_m"])
    poor = _poor_receiver(cmp, tol)
    acc = None if g.accuracy is None else g.accuracy[np.isfinite(g.accuracy) & (g.accuracy > 0)]
    if acc is None or acc.size == 0:
        if poor:
            return Check(s, WARN, f"{poor}, no accuracy stated: a poor receiver", fig)
        return na(s, f"no stated accuracy (scatter {fixed(scatter, 2)} m)", **fig)
    stated = float(np.median(acc))
    ratio = scatter / stated
    fig.update(stated_m=stated, ratio=ratio)
    why = f"scatter {fixed(scatter, 2)} m vs stated accuracy {fixed(stated, 2)} m"
    if ratio > tol.scatter_ratio_fail:
        return Check(s, FAIL, why, fig)
    if ratio > tol.scatter_ratio_warn:
        return Check(s, WARN, why, fig)
    if one_source:
        return Check(s, PASS, f"{why} (the truth's own positions)", fig)
    if stated > tol.max_fix_accuracy_m:
        use = (
            "the other streams are judged against the truth"
            if drive.truth is not None
            else "no reference for other streams"
        )
        return Check(
            s,
            WARN,
            f"median stated accuracy {fixed(stated, 1)} m > "
            f"{tol.max_fix_accuracy_m:g} m"
            + (f", {poor}" if poor else "")
            + f": a poor receiver ({use})",
            fig,
        )
    if poor:
        return Check(s, WARN, f"{poor}, stated accuracy {fixed(stated, 2)} m: a poor receiver", fig)
    return Check(s, PASS, why, fig)
