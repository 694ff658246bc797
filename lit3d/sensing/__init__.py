"""The sensor model and view geometry of the completion data, shared by data making and inference.

A shared room (below the task rooms, beside ``lit3d.render``): the data generator
(:mod:`datamodules.completion.depth_voxels`) and the depth-image pipeline of ``lit3d-reconstruct``
(:mod:`lit3d.reconstruct.grid`) both read the camera, noise and placement from here, so inference
places an object in the grid exactly as the training data did, from named constants.

- :mod:`lit3d.sensing.sensor`: :class:`~lit3d.sensing.sensor.Sensor` (camera, handedness, noise),
  the named settings :data:`~lit3d.sensing.sensor.SENSORS`, 3D-RecGAN++'s field of view.
- :mod:`lit3d.sensing.camera`: pinhole :class:`~lit3d.sensing.camera.Intrinsics`, back-projection
  of a depth image and projection (``lit3d-reconstruct`` and the body fit).
- :mod:`lit3d.sensing.placement`: the view geometry: :data:`~lit3d.sensing.placement.GRID_MARGIN` and
  :data:`~lit3d.sensing.placement.SURFACE_PUSH` (the placement every synthetic sample is made with) and
  :func:`~lit3d.sensing.placement.camera_rotation`.
"""
