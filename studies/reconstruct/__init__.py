"""The lit3d-reconstruct studies: the round trip mesh -> depth -> reconstruction (``check``), a depth PNG of
a mesh to try it on (``synthetic``)."""
