"""The hybrid's network in torch (training / export only; never imported at run time).

``HybridNet(features [B, 8, 6], prior [B, 4, 2]) -> correction [B, 4, 4]`` in RAW units:
per horizon H = (0.2, 0.4, 0.6, 0.8) s, (dx, dy) [m, heading frame] to add to the kf's
answer and (log var along the heading, log var across) [log m^2] of that residual.

All normalisation lives in the graph as buffers (like
:class:`posbench.predictors.lstm.model.LstmNet`), so the exported ONNX takes raw inputs:

- features standardised with ``feature_mean`` / ``feature_std`` (6,);
- the prior (kf answer minus the newest grid point, heading frame [m]) divided by
  ``prior_std`` (4, 2);
- the output is in residual units: correction = out[..., :2] * ``res_std`` (4, 2) and
  log var = out[..., 2:] + 2 log(``res_std``).

Architecture: encoder MLP (Linear + LeakyReLU) on the standardised features -> LSTM ->
last hidden state concatenated with the standardised prior (flattened, 8) -> decoder MLP
(Linear + LeakyReLU, Linear -> 16). The last layer starts at zero: an untrained net
answers correction 0 (the hybrid then answers exactly as the kf) with variance res_std^2.
"""

from __future__ import annotations

import numpy as np
import torch
from numpy.typing import ArrayLike
from torch import nn

from posbench.predictors.lstm.features import N_FEATURES

N_H = 4


def _stat(v: ArrayLike, shape: tuple[int, ...]) -> torch.Tensor:
    """``v`` broadcast to ``shape`` (a (4,) vector to (4, 2) per row) as float32."""
    a = np.asarray(v, dtype=np.float64)
    if len(shape) == 2 and a.ndim == 1:
        a = a[:, None]
    return torch.as_tensor(np.broadcast_to(a, shape).copy(), dtype=torch.float32)


class HybridNet(nn.Module):
    """Encoder MLP -> LSTM(hidden, lstm_layers) -> [h_last, prior] -> decoder MLP -> [B, 4, 4]."""

    # buffers (``register_buffer`` in ``__init__``), declared here with their type
    #: feature standardisation: mean and std (raw units), (6,) each
    feature_mean: torch.Tensor
    feature_std: torch.Tensor
    #: the prior's scale [m], (4, 2)
    prior_std: torch.Tensor
    #: the residual's scale [m] and 2 log of it, (4, 2) each
    res_std: torch.Tensor
    log_res_var: torch.Tensor

    def __init__(
        self,
        hidden: int = 48,
        lstm_layers: int = 1,
        enc_layers: int = 1,
        slope: float = 0.1,
        n_features: int = N_FEATURES,
    ) -> None:
        super().__init__()
        enc: list[nn.Module] = []
        width = n_features
        for _ in range(enc_layers):
            enc += [nn.Linear(width, hidden), nn.LeakyReLU(slope)]
            width = hidden
        self.encoder = nn.Sequential(*enc)
        self.lstm = nn.LSTM(hidden, hidden, num_layers=lstm_layers, batch_first=True)
        first = nn.Linear(hidden + 2 * N_H, hidden)  # built in this order: same random init
        last = nn.Linear(hidden, 4 * N_H)
        self.decoder = nn.Sequential(first, nn.LeakyReLU(slope), last)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        self.register_buffer("feature_mean", torch.zeros(n_features))
        self.register_buffer("feature_std", torch.ones(n_features))
        self.register_buffer("prior_std", torch.ones(N_H, 2))
        self.register_buffer("res_std", torch.ones(N_H, 2))
        self.register_buffer("log_res_var", torch.zeros(N_H, 2))

    def set_stats(
        self,
        feature_mean: ArrayLike,
        feature_std: ArrayLike,
        prior_std: ArrayLike,
        res_std: ArrayLike,
    ) -> None:
        """Normalisation statistics in raw units: feature mean / std (6,), prior scale [m]
        and residual scale [m] (scalars, (4,) per horizon or (4, 2) per horizon and axis)."""
        self.feature_mean.copy_(_stat(feature_mean, (N_FEATURES,)))
        self.feature_std.copy_(_stat(feature_std, (N_FEATURES,)))
        self.prior_std.copy_(_stat(prior_std, (N_H, 2)))
        rs = _stat(res_std, (N_H, 2))
        self.res_std.copy_(rs)
        self.log_res_var.copy_(2.0 * torch.log(rs))

    def forward_std(self, features: torch.Tensor, prior: torch.Tensor) -> torch.Tensor:
        """Raw inputs -> output in residual units [B, 4, 4] (correction / res_std, log var
        minus 2 log res_std): the training loss's units."""
        z = (features - self.feature_mean) / self.feature_std
        h, _ = self.lstm(self.encoder(z))
        p = (prior / self.prior_std).flatten(1)
        y = self.decoder(torch.cat([h[:, -1, :], p], dim=1))
        return y.view(-1, N_H, 4)

    def forward(self, features: torch.Tensor, prior: torch.Tensor) -> torch.Tensor:
        """features [B, 8, 6], prior [B, 4, 2] [m] -> [B, 4, 4]: dx, dy [m, heading frame],
        log var along, across [log m^2]."""
        y = self.forward_std(features, prior)
        return torch.cat([y[..., :2] * self.res_std, y[..., 2:] + self.log_res_var], dim=-1)
