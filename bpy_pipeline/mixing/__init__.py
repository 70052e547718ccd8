"""Real scans as backgrounds: synthetic objects cast into a real sweep by its own firings, exact per firing.

Pure (numpy and embreex); never imports bpy. The stages, one module each: :mod:`.firings`
(every firing of the sweep, hit or not), :mod:`.ground` (ground plane and collision index),
:mod:`.placement` (explicit boxes, the parking and KITTI papers' rules), :mod:`.cast` (the one
cast), :mod:`.noise` (the parking paper's noise injections), :mod:`.frame` (:func:`mix_frame`) and
:mod:`.convert` (a dense scan resampled into a sparser sensor). The two papers' own insertion methods,
the references it is measured against, are benchmarks/mixing_references.py.

The papers: *Annotation-free Generation of Training Data Using Mixed Domains for Segmentation of
3D LiDAR Point Clouds* ("the parking paper": synthetic cars in recorded scans of a car park) and
*Point Cloud Wall Projection for Realistic Road Data Augmentation* ("the KITTI paper").
"""

from .frame import MixedFrame, mix_frame
from .section import KittiRule, NoiseInjections, ObjectBox, ParkingRule, RealScanScene, RemoveBox

__all__ = ["MixedFrame", "mix_frame", "RealScanScene", "ObjectBox", "RemoveBox", "ParkingRule", "KittiRule", "NoiseInjections"]
