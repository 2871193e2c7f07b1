"""Files in and out: images, restricted unpickling, weights, checkpoints, asset specs, the GL platform."""
