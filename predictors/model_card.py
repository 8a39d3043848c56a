"""A human-readable model card (``MODEL_CARD.md``) from a learned predictor's ``model.json``.

``bench train`` writes it beside ``model.onnx`` and ``model.json``; the JSON stays the
machine-readable record (every file's sha256, the full history), the card says in a page
what the model is, what it saw, how it was chosen and how it did on its validation drives.
Pure text from the dict: no torch, no I/O but the one write in :func:`write_model_card`.
"""

from __future__ import annotations

from pathlib import Path


def _f(v: float | None, nd: int = 3) -> str:
    return "-" if v is None else f"{v:.{nd}f}"


def _data_lines(info: dict) -> list[str]:
    data = info.get("data") or {}
    out = []
    for p in data.get("paths") or []:
        files = p.get("files") or []
        out.append(
            f"- `{p['path']}`: {len(files)} files, "
            f"{sum(f.get('bytes', 0) for f in files) / 1e6:.1f} MB "
            "(sha256 of each in model.json `data.paths`)"
        )
    syn = (data.get("synthetic") or {}).get("drives") or 0
    if syn:
        out.append(
            f"- {syn} drives of the benchmark's synthetic generator "
            f"(seeds {data['synthetic']['generator_seeds'][0]}..., not the benchmark's own)"
        )
    cor = data.get("corpus") or {}
    if cor.get("drives"):
        env = cor["envelope"]["all"]
        out.append(
            f"- the vehicle-dynamics corpus: {cor['hours']:g} h, {cor['drives']} drives "
            f"(`{cor['generator']}`, seed {cor['seed']}): speed "
            f"{env['speed_min_mps']:.0f}-{env['speed_max_mps']:.0f} m/s, |lateral accel| "
            f"max {env['abs_lat_accel_max_mps2']:.1f} m/s^2, |curvature| max "
            f"{env['abs_curvature_max_inv_m']:.3f} 1/m"
        )
    mem = data.get("in_memory_drives") or []
    if mem:
        out.append(f"- {len(mem)} in-memory drives")
    out.append(
        "- never KITTI (evaluation only, non-commercial licence); the paper's 3 held-out "
        "routes are in the validation split, never trained on"
    )
    return out


def _validation_rows(info: dict) -> list[str]:
    val = info.get("validation") or {}
    rows = [
        "| windows | predictor | n | mean [m] | p50 [m] | p95 [m] |",
        "|---|---|---|---|---|---|",
    ]
    for key in [k for k in val if k == "all" or k.startswith("group:") or k.startswith("label:")]:
        for name, e in val[key].items():
            if e.get("n"):
                rows.append(
                    f"| {key} | {name} | {e['n']} | {_f(e.get('mean_m'))} | "
                    f"{_f(e.get('p50_m'))} | {_f(e.get('p95_m'))} |"
                )
    return rows


def _signed(v: float | None) -> str:
    return "-" if v is None or v != v else f"{v:+.4f}"


def _held_out_lines(info: dict) -> list[str]:
    """The hybrid against its prior (and the kf tuned by gradient) on held-out drives."""
    ho = info.get("held_out") or {}
    conds = ho.get("conditions") or {}
    if not conds:
        return []
    others = ["kf"] + (
        ["kf@gradient"]
        if any("hybrid_minus_kf@gradient" in (c.get("future") or {}) for c in conds.values())
        else []
    )
    head = (
        "| GPS condition | drives | query | "
        + " | ".join(f"{o} mean [m]" for o in others)
        + " | hybrid mean [m] | "
        + " | ".join(f"hybrid - {o} [m] (95 % CI)" for o in others)
        + " |"
    )
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for cond, c in conds.items():
        for kind in ("future", "now"):
            r = c.get(kind)
            if not r:
                continue
            cells = [cond, str(c.get("drives")), kind]
            cells += [_f(r.get(f"{o}_mean_m"), 4) for o in others]
            cells.append(_f(r.get("hybrid_mean_m"), 4))
            for o in others:
                d = r.get(f"hybrid_minus_{o}") or {}
                cells.append(
                    f"{_signed(d.get('diff'))} ({_signed(d.get('lo'))}, {_signed(d.get('hi'))})"
                )
            rows.append("| " + " | ".join(cells) + " |")
    return [
        "## Gain over its prior (held-out development drives, as run)",
        "",
        f"{ho.get('how', '')}. The hybrid here is the predictor as `bench run` runs it, its "
        "gate included.",
        "",
        *rows,
        "",
    ]


def _gate_lines(info: dict) -> list[str]:
    gate = info.get("gate") or {}
    if not gate:
        return []
    return [
        "## Gate",
        "",
        f"- shrinkage per horizon (0.2-0.8 s): {gate.get('shrink', 'none')}",
        "- input box: " + ("the training inputs' min/max" if "feature_min" in gate else "none"),
        f"- {gate.get('how', '')}",
        "",
    ]


def _limit_lines(info: dict) -> list[str]:
    data = info.get("data") or {}
    simulated = bool(
        (data.get("corpus") or {}).get("drives") or (data.get("synthetic") or {}).get("drives")
    )
    lines = [
        "- Validated on development drives only (the validation split above); the "
        "README's KITTI tables (never used for training or selection) show how it "
        "transfers to independent truth."
    ]
    if simulated:
        lines.append(
            "- Learned from a kinematic simulator (no tyre slip, no road slope, no IMU "
            "mounting error beyond the drawn biases) and ~1 h of real routes at ~10 m/s."
        )
    else:
        lines.append(
            "- Learned from real routes only (about an hour at ~10 m/s, one car per data "
            "set), scored against a cubic through their own fixes: it learns that "
            "reference's residual; elsewhere its gate decides how much of it to apply."
        )
    return lines


def model_card(info: dict, kind: str) -> str:
    """The card's Markdown for ``kind`` (``"lstm"`` or ``"hybrid"``) from model.json's dict."""
    tr = info.get("training") or {}
    data = info.get("data") or {}
    arch = info.get("architecture") or {}
    aug = tr.get("augmentation") or {}
    what = {
        "lstm": "the paper's system: cubic resampling of the fixes and IMU onto 8 samples "
        "200 ms apart, MLP encoder -> LSTM -> MLP decoder predicting the position "
        "200 ms after the newest fix",
        "hybrid": "the `kf` (its bank of linear Kalman filters, tuned) as a physics "
        "prior, plus a small MLP -> LSTM -> MLP that predicts the kf's residual (and its "
        "variance) at 0.2, 0.4, 0.6 and 0.8 s from the lstm's input window and the kf's "
        "own answers; a gate applies the correction only as far as it has earned it",
    }[kind]
    lines = [
        f"# Model card: `{kind}`",
        "",
        f"What it is: {what}.",
        "",
        "## Network",
        "",
        f"- architecture: {arch.get('encoder')}; LSTM {arch.get('lstm')}; decoder "
        f"{arch.get('decoder')}; {arch.get('parameters')} parameters",
        f"- input/output normalisation: {info.get('normalisation')}",
    ]
    if kind == "lstm":
        lines.append(
            f"- frame: {info.get('frame')}; form: {info.get('form', 'paper')}; "
            f"newest-fix offset in row 0: {info.get('fix_offset', False)}"
        )
        core = info.get("core")
        if core:
            lines.append(
                f"- runtime: `{core['file']}` beside the model holds the same network's "
                "weights without its in-graph normalisation (the fused step runs them in "
                "one compiled call; checked against model.onnx to 1e-5 m on load)"
            )
    else:
        lines.append(
            f"- horizons [s]: {info.get('horizons_s')}; prior: "
            f"{(info.get('prior') or {}).get('predictor')} with its tuned parameters "
            "per GPS condition (model.json `prior.params`)"
        )
        core = info.get("core")
        if core:
            lines.append(
                f"- runtime: `{core['file']}` beside the model holds the same network's "
                "weights with its normalisation folded in (run in one compiled call; "
                "checked against model.onnx on load)"
            )
    lines += [
        "",
        "## Data",
        "",
        *_data_lines(info),
        "",
        f"Split: {data.get('split')}. Train: {len(data.get('train_drives') or [])} drives, "
        f"{data.get('train_windows')} windows; validation: "
        f"{len(data.get('val_drives') or [])} drives, {data.get('val_windows')} windows "
        f"(drive names in model.json).",
        "",
        f"Augmentation: GPS profiles {aug.get('gps_profiles')} drawn from the truth of "
        f"drives that have one (fresh fix times each draw: {aug.get('time_jitter')}); "
        f"left-right mirroring: {aug.get('mirror')}.",
        "",
        "## Training",
        "",
        f"- command: `{info.get('command')}`",
        f"- seed {tr.get('seed')}; {tr.get('optimizer')} lr {tr.get('lr')}, batch "
        f"{tr.get('batch_size')}; {tr.get('scheduler')}",
        f"- loss: {tr.get('loss')}",
        f"- epochs: {tr.get('epochs_run')} of {tr.get('epochs_max')} run (stopped by "
        f"{tr.get('stopped_by', 'epochs')}); best epoch {tr.get('best_epoch')} kept; "
        f"{tr.get('seconds')} s on {tr.get('threads')} CPU threads",
        "",
        "## Validation (development drives, future point = fix + 0.2 s)",
        "",
        *_validation_rows(info),
        "",
        *_gate_lines(info),
        *_held_out_lines(info),
        "## Limits",
        "",
        *_limit_lines(info),
    ]
    return "\n".join(lines) + "\n"


def write_model_card(info: dict, out_dir: Path, kind: str) -> Path:
    """Write ``out_dir/MODEL_CARD.md``; returns its path."""
    path = Path(out_dir) / "MODEL_CARD.md"
    path.write_text(model_card(info, kind))
    return path
