"""bpy_pipeline: synthetic, automatically labeled LiDAR point clouds from procedural Blender scenes.

The pure part (config, geometry, lidar, io) runs anywhere; ``scenes``, ``export`` and
``pipeline.run`` need Blender's ``bpy`` module.
"""

__version__ = "0.1.0"
