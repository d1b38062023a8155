"""What exists in the world at a state: the scene description (boxes, cylinders, meshes, grain height field),
sensor geometry (camera, beam patterns, rig planning) and the exact ray caster. Shared by the renderer, the mock,
perception's accuracy check and the viewers; imports no participant package."""
