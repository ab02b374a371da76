"""The simulation: the pymunk world, the sensors and their limits, the compiled per-step kernels."""
