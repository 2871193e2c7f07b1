"""The optimiser's parameter groups: the learning rate each part of the avatar trains at.

Every weight trains at ``train.lr`` unless a setting gives its part a multiple of it: VolSDF's
β (``train.beta_lr_scale``, how fast the surface sharpens) and the tri-plane's features
(``train.triplane_lr_scale``: a feature plane is a table, each entry reached by few points a
step, and learns at grid rates, as Instant-NGP's and EG3D's do). A part at the plain rate
stays in the first group, so a checkpoint's group layout follows the settings.
"""

from __future__ import annotations

from torch import nn


def optimizer_groups(model: nn.Module, train) -> list[dict]:
    """Adam's groups for ``model`` (an :class:`~texvocab.method.field.AvatarField`) under the
    ``train`` settings: [{"params": [...]}, then {"params": [...], "lr": ...} per scaled part]."""
    scaled: list[tuple[list[nn.Parameter], float]] = []
    if train.beta_lr_scale != 1:
        scaled.append(([model.log_beta], train.beta_lr_scale))
    triplane = getattr(model, "triplane", None)
    if triplane is not None and train.triplane_lr_scale != 1:
        scaled.append((list(triplane.parameters()), train.triplane_lr_scale))
    apart = {id(p) for params, _ in scaled for p in params}
    groups = [{"params": [p for p in model.parameters() if p.requires_grad and id(p) not in apart]}]
    groups += [{"params": params, "lr": train.lr * scale} for params, scale in scaled]
    return groups
