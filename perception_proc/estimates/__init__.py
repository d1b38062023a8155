"""The offloading estimates from the points: the cart's rim (hence its pose), the grain height map and the
stream's impact point."""
