"""The paper's network in torch: MLP encoder -> LSTM -> MLP decoder (training/export only).

Input ``[batch, 8, 6]`` raw features (see :mod:`posbench.predictors.lstm.features`); every
normalisation lives inside the module as buffers, so the exported ONNX graph takes raw
features and returns raw next-sample features, the interface the runtime has always used.
``forward`` returns the many-to-many predictions (the next sample's features for each of
the 8 steps); :class:`FuturePoint` wraps it for export and returns only the last step (the
point 200 ms ahead), ``[batch, 6]``.

Two input/output forms (``form``, recorded in model.json):

- ``"paper"``: every feature standardised with the training windows' mean/std, the
  displacement output likewise (the form of the first bundled model).
- ``"speed"`` (default since issue 13): the same MLP -> LSTM -> MLP, made speed-invariant
  in-graph. The window's speed scale ``s`` [m per 0.2 s step] = mean length of its 7
  grid displacements + 0.02 m; the displacement inputs enter as ``(dx, dy) / s`` (in the
  heading frame ~(1, 0) at any speed), ``log s`` is a 7th encoder channel (standardised),
  the IMU/yaw/time inputs are standardised as before. The displacement output is a
  *residual* on the previous grid step: ``d_next = d_i + res_std * net`` (``d_0`` := ``d_1``),
  so the network learns what acceleration and turning change over 0.2 s (a few cm, at
  any speed) instead of the displacement itself (up to 8 m at 40 m/s, where a standardised
  output cannot resolve centimetres). The auxiliary outputs (next ax, ay, yaw, t) stay
  standardised as in the paper.

``fix_offset`` (model.json): row 0's dx, dy hold the newest fix minus the newest grid point
(:mod:`posbench.predictors.lstm.features`); in the ``"speed"`` form they enter divided by
``res_std`` (centimetres matter there at any speed), not by the speed scale.

LeakyReLU slope 0.1 (the paper's). This module imports torch: never import it from
the runtime path.
"""

from __future__ import annotations

import torch
from torch import nn

from posbench.predictors.lstm.features import N_FEATURES, SPEED_EPS_M

FORMS = ("speed", "paper")


class LstmNet(nn.Module):
    """Encoder MLP (``enc_layers`` x Linear+LeakyReLU) -> LSTM(hidden, lstm_layers) ->
    decoder MLP (Linear+LeakyReLU, Linear -> 6); ``form`` see the module doc."""

    # buffers (``register_buffer`` in ``__init__``), declared here with their type
    #: feature standardisation: mean and std (raw units), [n_features] each
    mean: torch.Tensor
    std: torch.Tensor
    #: ``"speed"`` form: mean and std of log(speed scale), scalars
    log_s_mean: torch.Tensor
    log_s_std: torch.Tensor
    #: ``"speed"`` form: the displacement residual's scale [m], (x, y)
    res_std: torch.Tensor

    def __init__(
        self,
        hidden: int = 64,
        lstm_layers: int = 1,
        enc_layers: int = 1,
        slope: float = 0.1,
        n_features: int = N_FEATURES,
        form: str = "paper",
        fix_offset: bool = False,
    ) -> None:
        super().__init__()
        if form not in FORMS:
            raise ValueError(f"form must be one of {FORMS}, not {form!r}")
        self.form = form
        self.fix_offset = fix_offset
        enc: list[nn.Module] = []
        width = n_features + (1 if form == "speed" else 0)
        for _ in range(enc_layers):
            enc += [nn.Linear(width, hidden), nn.LeakyReLU(slope)]
            width = hidden
        self.encoder = nn.Sequential(*enc)
        self.lstm = nn.LSTM(hidden, hidden, num_layers=lstm_layers, batch_first=True)
        self.decoder = nn.Sequential(
            nn.Linear(hidden, hidden), nn.LeakyReLU(slope), nn.Linear(hidden, n_features)
        )
        self.register_buffer("mean", torch.zeros(n_features))
        self.register_buffer("std", torch.ones(n_features))
        # "speed" form: log-scale standardisation and the residual's scale [m]
        self.register_buffer("log_s_mean", torch.zeros(()))
        self.register_buffer("log_s_std", torch.ones(()))
        self.register_buffer("res_std", torch.ones(2))

    def set_stats(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Feature standardisation statistics (raw units)."""
        self.mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
        self.std.copy_(torch.as_tensor(std, dtype=torch.float32))

    def set_speed_stats(self, log_s_mean: float, log_s_std: float, res_std: torch.Tensor) -> None:
        """``"speed"`` form: mean/std of log(speed scale) and the residual scale [m] (x, y)."""
        self.log_s_mean.fill_(float(log_s_mean))
        self.log_s_std.fill_(float(log_s_std))
        self.res_std.copy_(torch.as_tensor(res_std, dtype=torch.float32))

    # ------------------------------------------------------------------ pieces
    @staticmethod
    def speed_scale(x: torch.Tensor) -> torch.Tensor:
        """[B, 1, 1] mean grid step length + SPEED_EPS_M [m] of raw windows [B, 8, 6]."""
        d = x[:, 1:, :2]
        return torch.sqrt((d * d).sum(-1)).mean(1).reshape(-1, 1, 1) + SPEED_EPS_M

    @staticmethod
    def base_step(x: torch.Tensor) -> torch.Tensor:
        """[B, 8, 2] the skip of the ``"speed"`` form: each row's previous grid step
        (row 0 takes row 1's)."""
        d = x[:, :, :2]
        return torch.cat([d[:, 1:2], d[:, 1:]], dim=1)

    def encode_input(self, x: torch.Tensor) -> torch.Tensor:
        """Raw [B, 8, 6] -> the encoder's input (standardised; 7 channels for ``"speed"``)."""
        z = (x - self.mean) / self.std
        if self.form == "paper":
            return z
        s = self.speed_scale(x)
        ls = (torch.log(s) - self.log_s_mean) / self.log_s_std
        d = x[:, :, :2] / s
        if self.fix_offset:
            d = torch.cat([x[:, :1, :2] / self.res_std, d[:, 1:]], dim=1)
        return torch.cat([d, z[:, :, 2:], ls.expand(-1, x.shape[1], 1)], dim=-1)

    def core(self, x: torch.Tensor) -> torch.Tensor:
        """Raw [B, 8, 6] -> the decoder's standardised outputs [B, 8, 6]."""
        h, _ = self.lstm(self.encoder(self.encode_input(x)))
        return self.decoder(h)

    def target_std(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Raw targets [B, 8, 6] in the units :meth:`core` predicts (the training loss's)."""
        z = (y - self.mean) / self.std
        if self.form == "paper":
            return z
        r = (y[:, :, :2] - self.base_step(x)) / self.res_std
        return torch.cat([r, z[:, :, 2:]], dim=-1)

    def to_raw(self, x: torch.Tensor, o: torch.Tensor) -> torch.Tensor:
        """:meth:`core`'s standardised outputs -> raw next-sample features."""
        raw = o * self.std + self.mean
        if self.form == "paper":
            return raw
        return torch.cat([self.base_step(x) + o[:, :, :2] * self.res_std, raw[:, :, 2:]], dim=-1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Raw features [B, 8, 6] -> raw next-sample predictions [B, 8, 6]."""
        return self.to_raw(x, self.core(x))


class FuturePoint(nn.Module):
    """Runtime head: only the last step's prediction (the sample 200 ms ahead), [B, 6]."""

    def __init__(self, net: LstmNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n = self.net
        h, _ = n.lstm(n.encoder(n.encode_input(x)))
        o = n.decoder(h[:, -1, :])  # decode the last step only (the runtime's one output)
        raw = o * n.std + n.mean
        if n.form == "paper":
            return raw
        return torch.cat([x[:, -1, :2] + o[:, :2] * n.res_std, raw[:, 2:]], dim=-1)
