"""The avatar field's MLPs frozen at one pose for rendering (no autograd): every weight cast
once to the render precision, and the pose's first-layer columns folded into a bias once.

Under ``torch.autocast`` every call casts each weight again and the matrix library
prepares each new copy anew: measured on this project's machine (2 threads), a 128×128
bf16 layer on 10,000 rows took 1.66 ms through autocast against 0.25 ms with operands
already in bf16, and about 0.1 ms of fixed cost per layer on a handful of rows, eight
layers a field call. The frozen copies give the same numbers as the autocast path: the
same casts, made once (autocast's products of bf16 operands are bf16 products), and the
folded bias computed under autocast as the field computes it. In bfloat16 the
activations are tables (:mod:`texvocab.method.activation_table`), the same to the bit."""

from __future__ import annotations

import torch
from torch import nn

from texvocab.method.activation_table import ActivationTable
from texvocab.method.field_precision import resolve_precision

#: bfloat16 tables of the activations met so far, by the module's settings
_TABLES: dict[tuple, ActivationTable] = {}


class FrozenMLPs:
    """``field``'s feature projection, SDF and colour networks at ``ctx``'s pose in
    ``precision`` (a :data:`~texvocab.method.field_precision.PRECISIONS` name).

    Valid while the field's parameters are unchanged (:meth:`current`); for rendering
    only: no gradient reaches the field through it."""

    def __init__(self, field, ctx, precision: str):
        self.dtype = resolve_precision(precision)
        self.params = list(field.parameters())
        self.versions = self._versions()
        s = field.settings
        d_x = field.position_dim + s.feature_proj
        with torch.no_grad(), torch.autocast("cpu", dtype=self.dtype, enabled=self.dtype != torch.float32):
            first_w, first_b = field.first_sdf_layer(ctx, d_x)  # the bias as the field folds it
        self._proj = self._layers(nn.Sequential(field.feature_proj))
        self._sdf = self._layers(field.sdf_net, (first_w, first_b))
        self._color = self._layers(field.color_net)

    def _versions(self) -> tuple[int, ...]:
        return tuple(p._version for p in self.params)

    def current(self) -> bool:
        """Whether the field's parameters are still those this copy was made from."""
        return self._versions() == self.versions

    def _layers(self, net: nn.Sequential, first=None) -> list:
        """[(weight, bias) cast, or an activation module] in ``net``'s order; ``first``
        replaces the first layer's (weight, bias)."""
        out = []
        for i, m in enumerate(net):
            if isinstance(m, nn.Linear):
                w, b = first if (i == 0 and first is not None) else (m.weight, m.bias)
                out.append((self._cast(w), self._cast(b)))
            else:
                out.append(self._activation(m))
        return out

    def _activation(self, m: nn.Module):
        """``m``, or in bfloat16 its table (the same function to the bit, 3-4x faster)."""
        if self.dtype != torch.bfloat16:
            return m
        key = (
            type(m).__name__,
            *sorted((k, v) for k, v in vars(m).items() if isinstance(v, (int, float, bool))),
        )
        if key not in _TABLES:
            _TABLES[key] = ActivationTable(m)
        return _TABLES[key]

    def _cast(self, t: torch.Tensor) -> torch.Tensor:
        return t.detach().to(self.dtype).contiguous()

    @staticmethod
    def _run(layers: list, x: torch.Tensor) -> torch.Tensor:
        for layer in layers:
            x = torch.nn.functional.linear(x, *layer) if isinstance(layer, tuple) else layer(x)
        return x

    def project(self, features: torch.Tensor) -> torch.Tensor:
        """feature_proj(f) (N, P) in the frozen dtype, for f (N, C)."""
        return self._run(self._proj, features.to(self.dtype))

    def sdf_hidden(self, x: torch.Tensor) -> torch.Tensor:
        """sdf_net([x, q(Θ)]) (N, 1 + hidden) for the per-point inputs x (N, D)."""
        return self._run(self._sdf, x.to(self.dtype))

    def color(self, x: torch.Tensor) -> torch.Tensor:
        """color_net(x) (N, 3) before the sigmoid."""
        return self._run(self._color, x.to(self.dtype))
