"""``scene.population``: people, robot arms and cars placed into any built scene, re-drawn every frame.

``params`` (the section, its kinds' registry and checks) and ``placer`` (collision-free placement on the
scene's surfaces): pure; ``scene``: Blender (bpy), the pools of objects that show a frame's placements.
"""
