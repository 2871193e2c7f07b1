"""TexVocab: pose-driven avatars from multi-view video (CVPR 2024)."""

import os as _os

# OpenMP threads that spin while waiting for work made CPU rendering ~10x slower whenever
# another process held a core (bench/render_speed.py). Passive waiting costs each small op
# a thread wake-up on an idle machine (a 21-row linear layer: 185 us against 30 spinning),
# about 7% of a guided frame; bounded spinning (GOMP_SPINCOUNT 1e4) won that back idle but
# made frames 2x slower beside a busy process (README, "Tried and not kept"). Takes effect
# only if torch has not been imported yet; a user's value wins.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
