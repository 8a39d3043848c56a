"""The paper's network in torch: MLP encoder -> LSTM -> MLP decoder (training/export only).

Input ``[batch, 8, 6]`` raw features (see :mod:`predictors.lstm.features`); the
feature standardisation (mean/std computed on the training windows) lives inside the
module as buffers so the exported ONNX graph takes raw features. ``forward_std`` works
in standardised units (training loss); ``forward`` returns raw-unit predictions of the
next sample's features for each of the 8 steps (many-to-many); :class:`FuturePoint`
wraps it for export and returns only the last step (the point 200 ms ahead), ``[batch, 6]``.

LeakyReLU slope 0.1 (the paper's). This module imports torch: never import it from
the runtime path.
"""

from __future__ import annotations

import torch
from torch import nn

from predictors.lstm.features import N_FEATURES


class LstmNet(nn.Module):
    """Encoder MLP (``enc_layers`` x Linear+LeakyReLU) -> LSTM(hidden, lstm_layers) ->
    decoder MLP (Linear+LeakyReLU, Linear -> 6)."""

    def __init__(self, hidden: int = 64, lstm_layers: int = 1, enc_layers: int = 1,
                 slope: float = 0.1, n_features: int = N_FEATURES) -> None:
        super().__init__()
        enc: list[nn.Module] = []
        width = n_features
        for _ in range(enc_layers):
            enc += [nn.Linear(width, hidden), nn.LeakyReLU(slope)]
            width = hidden
        self.encoder = nn.Sequential(*enc)
        self.lstm = nn.LSTM(hidden, hidden, num_layers=lstm_layers, batch_first=True)
        self.decoder = nn.Sequential(nn.Linear(hidden, hidden), nn.LeakyReLU(slope),
                                     nn.Linear(hidden, n_features))
        self.register_buffer("mean", torch.zeros(n_features))
        self.register_buffer("std", torch.ones(n_features))

    def set_stats(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Feature standardisation statistics (raw units)."""
        self.mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
        self.std.copy_(torch.as_tensor(std, dtype=torch.float32))

    def forward_std(self, x_std: torch.Tensor) -> torch.Tensor:
        """Standardised [B, 8, 6] -> standardised next-sample predictions [B, 8, 6]."""
        h, _ = self.lstm(self.encoder(x_std))
        return self.decoder(h)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Raw features [B, 8, 6] -> raw next-sample predictions [B, 8, 6]."""
        return self.forward_std((x - self.mean) / self.std) * self.std + self.mean


class FuturePoint(nn.Module):
    """Runtime head: only the last step's prediction (the sample 200 ms ahead), [B, 6]."""

    def __init__(self, net: LstmNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        z = (x - self.net.mean) / self.net.std
        h, _ = self.net.lstm(self.net.encoder(z))
        y = self.net.decoder(h[:, -1, :])
        return y * self.net.std + self.net.mean
