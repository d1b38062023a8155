"""The grain: the unloading auger and its stream, the fill of the cart, and the fill in a tilted cart."""
