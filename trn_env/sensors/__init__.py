"""Sensor models: pure functions of (truth chunk, true terrain, rng, config), vectorised over a chunk."""
