"""The renderer (the paper's Unreal side): scene from the dynamics state, camera rig, depth-encoded images.

Modules: ``rig`` (plan_rig), ``scene`` (scene_from_state), ``raycast`` (exact reference), ``codec``
(encode_depth), ``heightfield`` (the grain surface), ``hfmesh`` (its draw mesh, flat blocks merged),
``gl_backend`` (moderngl, headless EGL), ``mock_backend`` (numpy ray caster), ``blocks`` (declare_blocks),
``participant`` (create). Importing this package, or any module of it, never touches GL:
moderngl is imported only when a GL renderer is made.
"""

__all__: list[str] = []
