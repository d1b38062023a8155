"""The camera sensors in perception: their images, their depth (stereo, time of flight), their post-process seam
and their points in the level frame (docs/cameras.md)."""
