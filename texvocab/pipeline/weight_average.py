"""An exponential moving average of the avatar's weights (``train.weight_average``).

With β near its floor the surface is sharp and each Adam step at a constant rate moves
the outline: a run's held-out score then swings by a dB or more within 50 steps, so where
a time budget happens to stop decides the result. The average of the last few hundred
steps' weights sits between those swings. Training steps the raw weights as before (the
average never feeds back), so a run's trajectory is the same with or without it; the
checkpoint's ``model`` holds the averaged weights, which evaluation, rendering and the
viewer read, and :data:`TRAINED_KEY` the raw ones, which ``--resume`` continues from.

The decay d is warmed up as min(d, (1 + n) / (10 + n)) after n updates, so the average
forgets the random initial weights within the first steps.
"""

from __future__ import annotations

import torch

#: Checkpoint key of the raw (trained) parameters when ``model`` holds their average.
TRAINED_KEY = "trained_weights"


class WeightAverage:
    """The running average of ``model``'s trainable parameters.

    Args:
        model: the avatar; its parameters with ``requires_grad`` are averaged.
        decay: d in (0, 1); the average after a step is d·avg + (1 − d)·w.
    """

    def __init__(self, model: torch.nn.Module, decay: float):
        if not 0.0 < decay < 1.0:
            raise ValueError(f"decay {decay}: expected 0 < decay < 1")
        self.decay = decay
        self.names = [n for n, p in model.named_parameters() if p.requires_grad]
        self.params = [p for p in model.parameters() if p.requires_grad]
        self.average = [p.detach().clone() for p in self.params]
        self.updates = 0

    def current_decay(self) -> float:
        """The decay the next update uses (warmed up over the first updates)."""
        return min(self.decay, (1.0 + self.updates) / (10.0 + self.updates))

    @torch.no_grad()
    def update(self) -> None:
        """Fold the parameters as they are now into the average (after an optimiser step)."""
        torch._foreach_lerp_(self.average, [p.detach() for p in self.params], 1.0 - self.current_decay())
        self.updates += 1

    def checkpoint_weights(self, state: dict[str, torch.Tensor]) -> tuple[dict, dict]:
        """Split a model state dict into (averaged state dict, raw trained parameters)."""
        averaged = dict(state)
        raw = {}
        for name, avg in zip(self.names, self.average, strict=True):
            raw[name] = state[name]
            averaged[name] = avg.clone()
        return averaged, {"parameters": raw, "updates": self.updates}

    @torch.no_grad()
    def load(self, averaged: dict[str, torch.Tensor], trained: dict, model: torch.nn.Module) -> None:
        """Resume: the average from a checkpoint's ``model``, the raw weights into ``model``."""
        raw = trained["parameters"]
        for name, p, avg in zip(self.names, self.params, self.average, strict=True):
            avg.copy_(averaged[name])
            p.copy_(raw[name])
        self.updates = int(trained["updates"])


def trained_state(checkpoint: dict) -> dict[str, torch.Tensor]:
    """A checkpoint's model state with the raw trained weights in place of their average
    (its ``model`` itself when it holds no average)."""
    state = dict(checkpoint["model"])
    state.update(checkpoint.get(TRAINED_KEY, {}).get("parameters", {}))
    return state
