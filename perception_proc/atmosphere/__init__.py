"""Dust and the grain stream between a sensor and its targets: the dust model, its effect on the LiDAR and on
the cameras, and the stream as particles (docs/field.md)."""
