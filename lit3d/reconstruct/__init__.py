"""``lit3d-reconstruct``: a depth image from a camera -> a completed mesh in the camera frame.

Modules: ``depth_io`` (readers, one-line errors), ``backproject`` (intrinsics, points),
``segment`` (cutting the object out), ``grid`` (the checkpoint's training geometry),
``pipeline`` (the steps), ``canonical`` (the non-rigid chain), ``outputs`` (files),
``figure`` (the labelled picture), ``synthetic`` (depth renders of known meshes for checks).
It sits between ``lit3d.cli`` and the task rooms (import-linter contract in pyproject.toml).
"""
