"""TexVocab: pose-driven avatars from multi-view video (CVPR 2024)."""
import os as _os

# OpenMP threads that spin while waiting for work made CPU rendering ~10x slower whenever
# another process held a core (bench/render_speed.py). Passive waiting costs nothing on an
# idle machine. Takes effect only if torch has not been imported yet; a user's value wins.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
