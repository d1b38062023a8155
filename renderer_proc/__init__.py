"""The renderer (the paper's Unreal side): scene from the dynamics state, camera rig, depth-encoded images.

Backends: ``gl`` (moderngl, headless EGL; its programs in ``shaders/``) and ``mock`` (the exact ray cast, no
OpenGL). At the top: ``codec`` (the Eqs 1-2 encoder), ``projection``, ``cameras`` (the camera sensors),
``blocks`` (declare_blocks), ``participant`` (create). The scene, rig and ray casters are ``cosim.world``'s.
docs/paper.md maps each block and equation of the paper to its function and its test. Importing this package, or
any module of it, never touches GL: moderngl is imported only when a GL renderer is made.
"""

__all__: list[str] = []
