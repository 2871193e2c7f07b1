"""TexVocab: pose-driven avatars from multi-view video (CVPR 2024)."""
