"""Perception process (the paper's MATLAB side): depth decode, LiDAR resampling, noise, cart boundary, grain
height map, impact location, accuracy against truth.

Modules: ``patterns`` (beam tables), ``codec`` (Eq 3), ``resample`` / ``resample_offset`` (Eqs 5-7, co-located
and general), ``lidar`` (limits, noise, point records), ``rim`` / ``heightmap`` / ``impact`` (the offloading
algorithms), ``pipeline`` (one frame, pure), ``participant`` (the ring member), ``blocks``, ``accuracy``,
``summary``, ``accuracy_report``. Importing the
package imports nothing else.
"""
