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
        "hybrid": "the tuned linear Kalman filter `kf` as a physics prior, plus a small "
        "MLP -> LSTM -> MLP that predicts the kf's residual (and its variance) "
        "at 0.2, 0.4, 0.6 and 0.8 s from the lstm's input window and the kf's "
        "own answers",
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
                f"- runtime: `{core['file']}` beside the model is the same network "
                "without its in-graph normalisation (the fused step runs it; checked "
                "against model.onnx to 1e-5 m on load)"
            )
    else:
        lines.append(
            f"- horizons [s]: {info.get('horizons_s')}; prior: "
            f"{(info.get('prior') or {}).get('predictor')} with its tuned parameters "
            "per GPS condition (model.json `prior.params`)"
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
        "## Limits",
        "",
        "- Validated on synthetic corpus drives and the paper's routes only; the "
        "README's KITTI tables (never used for training or selection) show how it "
        "transfers to independent truth.",
        "- Learned from a kinematic simulator (no tyre slip, no road slope, no IMU "
        "mounting error beyond the drawn biases) and ~1 h of real routes at ~10 m/s.",
    ]
    return "\n".join(lines) + "\n"


def write_model_card(info: dict, out_dir: Path, kind: str) -> Path:
    """Write ``out_dir/MODEL_CARD.md``; returns its path."""
    path = Path(out_dir) / "MODEL_CARD.md"
    path.write_text(model_card(info, kind))
    return path
