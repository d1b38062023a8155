"""The OpenGL backend (moderngl, headless EGL): the LiDAR's camera rig, the beam-native view, the camera
sensors and the grain surface's mesh; its programs are in ``renderer_proc/shaders/``."""
