"""The simulated LiDAR: the depth decoder of Eq 3, the resampling of camera images into beams (Eqs 6-7,
corrected), beam-native ranges, range limits and noise."""
