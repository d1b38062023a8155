"""Perception process (the paper's MATLAB side): the LiDAR sensor model built on the camera images, the camera
sensors, and the offloading estimates with their accuracy against truth.

Subpackages by the paper's blocks: ``lidar`` (Eq 3 decoder, the Eqs 6-7 resampling, beam-native ranges, range
limits and noise), ``cameras`` (images, depth models, effects, points), ``atmosphere`` (dust and the stream as
particles), ``estimates`` (cart boundary, grain height map, impact location), ``accuracy`` (against truth). At
the top: ``pipeline`` (one frame, pure), ``participant`` (the ring member), ``protocol`` and ``staged`` (the
plug-in point and the built-in algorithm), ``blocks``, ``summary``. docs/paper.md maps each block and equation of
the paper to its function and its test. Importing the package imports nothing else.
"""
