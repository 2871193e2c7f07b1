"""A TORCH_HOME made by the test: pretrained weights present or absent, the user's untouched."""


def torch_home_with(root, state_dicts: dict):
    """``root`` as a TORCH_HOME holding ``{file name: state dict}`` in hub/checkpoints/."""
    import torch

    (root / "hub" / "checkpoints").mkdir(parents=True, exist_ok=True)
    for name, state in state_dicts.items():
        torch.save(state, root / "hub" / "checkpoints" / name)
    return root
